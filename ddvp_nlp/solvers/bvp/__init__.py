"""bvp"""

from .solve import solve_bvp

__all__ = ["solve_bvp"]
