"""march"""

from .ensemble import march_ensemble
from .solve import march

__all__ = ["march", "march_ensemble"]
