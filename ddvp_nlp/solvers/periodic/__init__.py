"""periodic"""

from .family import solve_periodic_family
from .solve import solve_periodic

__all__ = ["solve_periodic", "solve_periodic_family"]
