"""ddvp_nlp: the difference discrete variational principle with variable time steps, on CasADi.

Node times are unknowns; varying them gives a discrete energy equation, so the schemes are
symplectic and conserve energy. See THEORY.md for the equations in this code's notation.
"""

from .errors import InputError
from .higher import HigherOrderScene, HigherOrderSystem
from .lagrangian import Lagrangian, LagrangianSystem
from .march import march
from .scenes import Scene, list_scenes, load_scene
from .scheme import Scheme
from .solution import Solution, Status
from .system import HamiltonianSystem

__all__ = ["HamiltonianSystem", "HigherOrderScene", "HigherOrderSystem", "InputError",
           "Lagrangian", "LagrangianSystem", "Scene",
           "Scheme", "Solution", "Status", "list_scenes", "load_scene", "march"]
