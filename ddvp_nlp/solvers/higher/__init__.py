"""higher"""

from .solve import march_higher, solve_bvp_higher

__all__ = ["march_higher", "solve_bvp_higher"]
