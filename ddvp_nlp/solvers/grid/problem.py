"""What a grid problem is: the protocol an assembly implements, the request every grid solver
receives, and the result every grid solver returns (the contract of ``grid/__init__.py``)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Generic, Protocol, TypeVar

import casadi as ca
import numpy as np

from ...cache import PROBLEMS
from ...discrete.scheme import Scheme
from ...errors import InputError
from ..options import Compilation, GridOptions

Data = TypeVar("Data")


class GridLayout(Protocol):
    """Where the unknowns sit in ``x``."""

    @property
    def size(self) -> int:
        """Number of unknowns (and of rows: the system is square)."""

    @property
    def bandwidth(self) -> int:
        """Lower and upper bandwidth of the Jacobian; wider than 32 means sparse LU (a
        Jacobian that is not banded gives the system's size)."""

    def time_index(self) -> np.ndarray:
        """Positions of the node times ``t_0 .. t_{N-1}`` in ``x``, in order."""


class GridProblem(Protocol[Data]):
    """The square system ``F(x) = 0`` of one grid, as the grid solvers see it.

    ``data`` is the problem's own data (ends, energy, section, parameters): one assembly,
    built once per system and grid size, serves every problem of that shape."""

    layout: GridLayout

    def evaluate(self, x: np.ndarray, data: Data, jacobian: bool = True):
        """``(F, J)``: the residual ``F(x)`` (a new array of ``layout.size``) and, if asked,
        the Jacobian in the assembly's own form (``None`` if not asked), valid until the next
        evaluation with ``jacobian=True``."""

    def banded(self, jacobian) -> np.ndarray:
        """``J`` in LAPACK ``gbtrf`` storage, ``(3 w + 1, size)`` in Fortran order; it may be
        factored in place. Asked for only when ``layout.bandwidth <= WIDEST_BAND`` (or
        ``linear="banded"``): an assembly whose Jacobian is not banded (a periodic grid's) gives
        a bandwidth of its size and need not have this method, and its family refuses
        ``linear="banded"``."""

    def sparse(self, jacobian):
        """``J`` as a scipy sparse matrix."""

    def release(self) -> None:
        """Drop the memory the Jacobian's storage holds (the assembly stays cached)."""

    def parameter_jacobian(self, x: np.ndarray, data: Data):
        """``dF/dtheta`` at ``x``, ``(size, len(theta))`` as a scipy sparse matrix, from the
        same CasADi expressions as ``F`` (`parameter_blocks`). Solvers do not use it yet: it is
        where a forward sensitivity ``J dx/dtheta = -dF/dtheta`` or an adjoint
        ``J^T lambda = g`` (``Factorization.solve_transposed``) takes ``dF/dtheta`` from."""


def parameter_blocks(function: ca.Function, shared: int, grid, theta: np.ndarray,
                     columns: int | None = None) -> np.ndarray:
    """``d out_0 / d input_shared`` of a per-block function over ``count`` blocks,
    ``(count, rows, columns)``: ``grid`` the per-block inputs ``(count, size)`` in the order of
    the function's inputs without the shared one, ``theta`` the shared input, ``columns`` the
    leading columns kept (the parameters of a shared input that also carries a scale). The
    derivative is CasADi's of the function's own expression, evaluated on its virtual machine
    (one mapped call)."""
    inputs = function.sx_in()
    expression = function.call(inputs)[0]
    derivative = ca.Function(function.name() + "_theta", inputs,
                             [ca.densify(ca.jacobian(expression, inputs[shared]))])
    count = grid[0].shape[0]
    width = inputs[shared].numel()
    arguments = [np.ascontiguousarray(a, float).T for a in grid]
    arguments.insert(shared, np.asarray(theta, float))
    values = np.asarray(derivative.map(count)(*arguments)).reshape(
        expression.numel(), count, width).transpose(1, 0, 2)
    return values[:, :, :width if columns is None else columns]


@dataclass(frozen=True)
class BorderedLayout:
    """The layout of a problem bordered by one more unknown (a continuation's parameter or
    arclength): ``base``'s unknowns, then one; its Jacobian's last row and column are full, so
    it is not banded."""

    base: object

    @property
    def size(self) -> int:
        return self.base.size + 1

    @property
    def bandwidth(self) -> int:
        return self.size

    def time_index(self) -> np.ndarray:
        return self.base.time_index()


@dataclass
class GridResult:
    """What a grid solver returns: the point it ended on, whether it says it converged, what
    happened in words, and its iteration history. Whether the point solves the problem is the
    caller's verification to decide.

    ``iterations`` counts the steps taken; ``last_iteration`` (the grid Newton's) is the
    iteration the solve ended in: ``k`` when iteration ``k``'s test, solve or step stopped it
    (``k - 1`` steps taken, or ``k`` for a step test that halts after its step; 1 for a start
    that is refused), ``max_iter`` when it ran out."""

    x: np.ndarray
    converged: bool
    outcome: str
    iterations: int
    residual_norms: list = field(default_factory=list)
    step_lengths: list = field(default_factory=list)
    last_iteration: int = 0


def timed_out(said: str) -> bool:
    """Whether a grid solver's words say it stopped at its time limit (the grid Newton's
    ``"time limit reached ..."``, IPOPT's ``Maximum_WallTime_Exceeded``), whatever prefix a
    family put before them."""
    return "time limit reached" in said or "Maximum_WallTime_Exceeded" in said


@dataclass
class GridRequest(Generic[Data]):
    """The checked inputs of one grid solve (fixed ends, a periodic orbit, a higher-order
    problem): what every family's phases and solvers receive.

    Attributes:
        system, scheme: the system and the scheme whose equations are solved.
        nodes: the grid's nodes, ``nodes=`` of the family's function (a closed orbit of ``N``
            intervals has ``N + 1`` nodes, its last the first's image; `intervals`).
        theta: the parameter vector.
        data: the family's problem data (``bvp.Boundary``, ``periodic.Orbit``,
            ``higher.problem.FixedNodes``).
        options: the `GridOptions`, with the family's defaults in place of ``None``.
        compilation: which compiled code the assemblies and the band LU run.
        tau_floor: the smallest step the iterates may take (resolved).
        progress: report each iteration on stderr.
        deadline: ``time.perf_counter()`` value after which the solve stops.
        build_s: seconds spent building problems (`built`).
        phases: one `Stage` (``policy.py``) per solver run made for this request, in order.
    """

    system: object
    scheme: Scheme
    nodes: int
    theta: np.ndarray
    data: Data
    options: GridOptions
    compilation: Compilation = field(default_factory=Compilation)
    tau_floor: float = 0.0
    progress: bool = False
    deadline: float | None = None
    build_s: float = 0.0
    phases: list = field(default_factory=list)

    @property
    def intervals(self) -> int:
        """The grid's intervals, ``nodes - 1``."""
        return self.nodes - 1

    @property
    def solver(self) -> str:
        return self.options.solver

    @property
    def tol(self) -> float:
        return self.options.tol

    @property
    def max_iter(self) -> int:
        return self.options.max_iter

    @property
    def linear(self) -> str:
        return self.options.linear

    @property
    def verbose(self) -> bool:
        return self.options.verbose

    def start_clock(self) -> float:
        """Now; the deadline set from ``options.time_limit``."""
        now = time.perf_counter()
        if self.options.time_limit is not None:
            self.deadline = now + self.options.time_limit
        return now

    def remaining(self) -> float | None:
        """Seconds left before the deadline (``None``: no deadline)."""
        return None if self.deadline is None else max(self.deadline - time.perf_counter(), 0.0)

    def built(self, key, build):
        """``build()`` cached per system under ``key`` (``cache.PROBLEMS``), its time added to
        `build_s`."""
        started = time.perf_counter()
        value = PROBLEMS.get(self.system, key, build)
        self.build_s += time.perf_counter() - started
        return value

    def forget(self, dropped) -> None:
        """Drop this system's built problems whose key ``dropped(key)`` is true, before a
        large one is built in their place."""
        PROBLEMS.discard(self.system, dropped)


def check_energy_problem(system, scheme: Scheme, what: str) -> None:
    """A problem at a prescribed energy (``what``, said in the message) needs an autonomous
    ``H`` and a scheme with an energy equation."""
    if system.time_dependent:
        raise InputError(f"system {system.name!r}: H depends on t; {what} needs an autonomous H")
    if not scheme.variable_steps:
        raise InputError(f"scheme {scheme.rule!r} has no energy equation; {what} needs 'vddvp' "
                         f"or 'lee'")
