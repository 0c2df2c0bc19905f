"""ddvp_nlp: the difference discrete variational principle with variable time steps, on CasADi.

Node times are unknowns; varying them gives a discrete energy equation, so the schemes are
symplectic and conserve energy. See THEORY.md for the equations in this code's notation.
"""

from .discrete.scheme import Scheme
from .errors import InputError
from .physics.hamiltonian import HamiltonianSystem
from .physics.higher import HigherOrderSystem
from .physics.lagrangian import Lagrangian, LagrangianSystem
from .scenes import HigherOrderScene, Scene, list_scenes, load_scene
from .solution import Solution, Status
from .solvers.march import march

__all__ = ["HamiltonianSystem", "HigherOrderScene", "HigherOrderSystem", "InputError",
           "Lagrangian", "LagrangianSystem", "Scene",
           "Scheme", "Solution", "Status", "list_scenes", "load_scene", "march"]
