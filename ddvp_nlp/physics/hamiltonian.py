"""A mechanical system declared by its Hamiltonian ``H(q, p, t)``.

The user writes ``H`` as a plain Python function on CasADi symbols::

    def hamiltonian(q, p, t, eps, omega):
        return p[0]**2 / 2 + (1 - ca.cos(q[0])) * (1 - eps * ca.sin(omega * t))

``q`` and ``p`` are column vectors of length ``n``, ``t`` a scalar and every named parameter a
scalar symbol. The function is called once, symbolically, when the system is made; whether ``H``
depends on ``t`` is read off the expression, not declared.
"""

from __future__ import annotations

import contextlib
import inspect
import linecache
import os
import re
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..blocks import evaluate_columns
from ..cache import cached
from ..errors import InputError
from ..validation import check_angles, check_integer, check_parameter_values


@dataclass(eq=False)
class HamiltonianSystem:
    """``H(q, p, t; params)`` on ``R^n x R^n x R``.

    Attributes:
        hamiltonian: ``H(q, p, t, **params)`` returning a scalar CasADi expression.
        n: number of degrees of freedom.
        params: parameter names and default values.
        name: a label for reports.
        angles: the coordinates that are angles (``("q2",)``: ``H`` is ``2 pi``-periodic in
            them): the accuracy check judges one that winds within a turn, not against the
            turns it made (an azimuth).
        constraints: holonomic constraints ``g(q, t, **params)`` returning a CasADi vector
            (``physics/constraints.py``), or ``None``; the system then has ``G`` (the SX
            column of ``g`` in ``q, t, theta``) and ``n_constraints``.
    """

    hamiltonian: Callable[..., object]
    n: int
    params: Mapping[str, float] = field(default_factory=dict)
    name: str = "system"
    angles: tuple = ()
    constraints: Callable[..., object] | None = None

    lagrangian_form = False  # the discrete equations come from H (LagrangianSystem: from L)

    def __post_init__(self):
        self._symbols()
        self.H = self._user_expression("hamiltonian", self.hamiltonian, self.p)
        self._finish()
        self._constrain()

    def _symbols(self):
        self.n = check_integer("n", self.n)
        self.angle_indices = check_angles(self.angles, self.n)
        self.params = check_parameter_values(self.params, {k: 0.0 for k in self.params},
                                             owner=f"system {self.name!r}")
        self.q = ca.SX.sym("q", self.n)
        self.p = ca.SX.sym("p", self.n)
        self.t = ca.SX.sym("t")
        self.theta = ca.SX.sym("theta", len(self.params))

    def _user_expression(self, kind: str, function, second) -> ca.SX:
        """``function(q, second, t, **params)`` on the symbols, checked: scalar, SX, and using
        no symbol it was not given."""
        symbols = {name: self.theta[i] for i, name in enumerate(self.params)}
        try:
            with numpy_on_symbols(f"{kind} of {self.name!r}"):
                value = function(self.q, second, self.t, **symbols)
        except InputError:
            raise
        except Exception as exc:  # the user's function; say whose it was
            raise InputError(
                f"{kind} of {self.name!r} failed on symbolic input: "
                f"{type(exc).__name__}: {exc}") from exc
        expression = as_scalar_expression(value, self.name, kind)
        given = ca.vertcat(self.q, second, self.t, self.theta)
        stray = [s.name() for s in ca.symvar(expression) if not ca.depends_on(s, given)]
        if stray:
            raise InputError(
                f"{kind} of {self.name!r} depends on symbols it was not given: "
                f"{', '.join(stray)}")
        return expression

    def _finish(self):
        self.time_dependent = bool(ca.depends_on(self.H, self.t))
        self.H_function = ca.Function("H", [self.q, self.p, self.t, self.theta], [self.H],
                                      ["q", "p", "t", "theta"], ["H"])
        varying = varying_part(self.H, ca.vertcat(self.q, self.p, self.t))
        self.H_varying_function = self.H_function if varying is self.H else ca.Function(
            "H_varying", [self.q, self.p, self.t, self.theta], [varying],
            ["q", "p", "t", "theta"], ["H"])

    def _constrain(self):
        """``G`` and ``n_constraints`` from ``constraints`` (checked, ``constraints.py``)."""
        from .constraints import constraint_column  # loaded by a system that has some

        self.G = ca.SX(0, 1) if self.constraints is None else \
            constraint_column(self, self.constraints, numpy_on_symbols, as_sx)
        self.n_constraints = int(self.G.size1())
        # H is not conserved where the constraints move (a rotating hoop, a rod whose length
        # changes): the accuracy check's energy tests read `energy_varies`
        self.energy_varies = self.time_dependent or bool(
            self.n_constraints and ca.depends_on(self.G, self.t))

    def parameter_vector(self, values: Mapping[str, object] | None = None) -> np.ndarray:
        """Numeric ``theta`` in declaration order, defaults filled in, names checked."""
        resolved = check_parameter_values(values or {}, self.params,
                                          owner=f"system {self.name!r}")
        return np.array([resolved[k] for k in self.params], dtype=float)

    def energy(self, q, p, t, theta) -> np.ndarray:
        """``H`` at each row of ``q``, ``p`` (shape ``(N, n)``) and ``t`` (shape ``(N,)``)."""
        q = np.atleast_2d(np.asarray(q, float))
        p = np.atleast_2d(np.asarray(p, float))
        t = np.atleast_1d(np.asarray(t, float))
        if not q.shape[0]:
            return np.zeros(0)
        return evaluate_columns(self, self.H_function, [q.T, p.T, t[None, :]], theta).ravel()



def varying_part(expression: ca.SX, symbols: ca.SX) -> ca.SX:
    """``expression`` without the terms of its outermost sum that depend on none of
    ``symbols`` (a constant, a function of the parameters alone): ``H + c`` gives ``H``,
    formed on the symbols, so that a difference of two values (the energy equation of the
    discrete schemes, the verdict's energy tests) is free of the round-off of ``c``. The
    same object where there is no such term (then every value is bit for bit the same).

    The sum is walked without recursion (a lattice's ``H`` is a chain of thousands of
    additions) and each of its terms is asked once whether it depends on the symbols, so the
    cost is that of one pass over the expression."""
    wanted = {symbol.element_hash() for symbol in ca.symvar(symbols)}
    pending, done, found = [(expression, False)], [], False
    while pending:
        node, children_done = pending.pop()
        if not (node.is_op(ca.OP_ADD) or node.is_op(ca.OP_SUB)):
            if any(symbol.element_hash() in wanted for symbol in ca.symvar(node)):
                done.append((node, True))
            else:
                found = True
                done.append((ca.SX(0), False))
        elif not children_done:
            pending += [(node, True), (node.dep(1), False), (node.dep(0), False)]
        else:
            (right, right_varies), (left, left_varies) = done.pop(), done.pop()
            if not (left_varies or right_varies):
                done.append((ca.SX(0), False))
            else:
                done.append((left + right if node.is_op(ca.OP_ADD) else left - right, True))
    return done[0][0] if found else expression


# CasADi's own warning when numpy's functions meet its symbols (20 lines about its numpy mode)
NUMPY_ON_CASADI = "a numpy function was called on a casadi value"


@contextlib.contextmanager
def numpy_on_symbols(whose: str):
    """Run a user's function on CasADi symbols with CasADi's 20-line warning about numpy's
    functions (``np.cos(q[0])``) replaced by one of the tool's own, once, naming ``whose``
    function, the numpy functions its line calls and where: the expression is right (numpy
    hands the call to CasADi), but the user should write ``ca.cos``. Every other warning goes
    on as it would have."""
    calls: list[str] = []
    previous = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if NUMPY_ON_CASADI in str(message):
            calls.append(_numpy_call_site())
        else:
            previous(message, category, filename, lineno, file, line)

    with warnings.catch_warnings():
        warnings.filterwarnings("always", message=f".*{NUMPY_ON_CASADI}")
        warnings.showwarning = show
        yield
    if calls:
        sites = sorted(set(calls))
        warnings.warn(f"{whose} uses numpy's functions on CasADi symbols ({'; '.join(sites)}); "
                      "use casadi's (ca.cos, ca.exp, ...) instead", RuntimeWarning, stacklevel=3)


def _numpy_call_site() -> str:
    """``FILE:LINE np.cos`` of the innermost frame outside numpy, CasADi and this module:
    the user's line that called numpy on a symbol."""
    frame = inspect.currentframe()
    inside = (os.path.dirname(np.__file__), os.path.dirname(ca.__file__))
    while frame is not None and (frame.f_code.co_filename.startswith(inside)
                                 or frame.f_code.co_filename in (warnings.__file__, __file__)):
        frame = frame.f_back
    if frame is None:
        return "numpy"
    source = linecache.getline(frame.f_code.co_filename, frame.f_lineno)
    names = sorted(set(re.findall(r"\b(?:np|numpy)\.(\w+)", source)))
    where = f"{os.path.basename(frame.f_code.co_filename)}:{frame.f_lineno}"
    return f"{where}: {', '.join('np.' + name for name in names) or 'numpy'}"


def as_sx(value, name: str, kind: str, wanted: str = "a CasADi expression") -> ca.SX:
    """What a user's function of the system's symbols returned (``kind`` of system ``name``),
    as SX: a number taken as a constant; an MX expression, or anything that is not ``wanted``
    (SX or DM), refused by name."""
    if isinstance(value, (int, float, np.integer, np.floating)):
        value = ca.SX(float(value))
    if isinstance(value, ca.MX):
        raise InputError(f"{kind} of {name!r} returned an MX expression; use the SX "
                         "symbols it is given (ca.sin, ca.cos, ... work on them)")
    if not isinstance(value, (ca.SX, ca.DM)):
        raise InputError(f"{kind} of {name!r} must return {wanted}, got "
                         f"{type(value).__name__}")
    return ca.SX(value)


def as_scalar_expression(value, name: str, kind: str = "hamiltonian") -> ca.SX:
    value = as_sx(value, name, kind)
    if value.shape != (1, 1):
        raise InputError(f"{kind} of {name!r} must be scalar, got shape "
                         f"{value.shape[0]}x{value.shape[1]}")
    return value


def derivatives_function(system: HamiltonianSystem) -> ca.Function:
    """``(q, p, t, theta) -> (H, dH/dq, dH/dp, dH/dt)``."""
    def build():
        H = system.H
        return ca.Function(
            "dH", [system.q, system.p, system.t, system.theta],
            [H, ca.gradient(H, system.q), ca.gradient(H, system.p), ca.gradient(H, system.t)],
            ["q", "p", "t", "theta"], ["H", "H_q", "H_p", "H_t"])
    return cached(system, "dH", build)


def site_density_weight_function(system: HamiltonianSystem) -> ca.Function:
    """``w(q, p, t, theta) = f' H_zz f`` with ``f = (H_p, -H_q)``.

    Expanding the midpoint energy of a step of length ``tau`` from ``z`` along the flow gives
    ``H(z_mid) = H(z) - tau^2 w / 8 + O(tau^3)``; for ``H = p^2/2 + V`` it is the paper's
    ``V'' p^2 + V'^2`` (section 4), and the energy rules' steps follow ``tau ~ w^(-1/3)``.
    """
    def build():
        z = ca.vertcat(system.q, system.p)
        f = ca.vertcat(ca.gradient(system.H, system.p), -ca.gradient(system.H, system.q))
        w = ca.mtimes([f.T, ca.hessian(system.H, z)[0], f])
        return ca.Function("site_density_weight", [system.q, system.p, system.t, system.theta],
                           [w], ["q", "p", "t", "theta"], ["w"])
    return cached(system, "site_density_weight", build)


def vector_field_function(system: HamiltonianSystem) -> ca.Function:
    """``f(z, t, theta) = (H_p, -H_q)`` with ``z = (q, p)``: Hamilton's equations ``z' = f``.

    Written here once; the march's predictor, the explicit baselines, scipy's right-hand side
    and the site-density weight all use it."""
    def build():
        n = system.n
        z, t = ca.SX.sym("z", 2 * n), ca.SX.sym("t")
        _, H_q, H_p, _ = derivatives_function(system)(z[:n], z[n:], t, system.theta)
        return ca.Function("f", [z, t, system.theta], [ca.vertcat(H_p, -H_q)],
                           ["z", "t", "theta"], ["f"])
    return cached(system, "vector_field", build)


def flow_jacobian_function(system: HamiltonianSystem) -> ca.Function:
    """``(z, t, theta) -> (f, A)``: Hamilton's vector field and its Jacobian ``A = df/dz``."""
    def build():
        z, t = ca.SX.sym("z", 2 * system.n), ca.SX.sym("t")
        f = vector_field_function(system)(z, t, system.theta)
        return ca.Function("f_A", [z, t, system.theta], [f, ca.jacobian(f, z)],
                           ["z", "t", "theta"], ["f", "A"])
    return cached(system, "flow_jacobian", build)


def flow_time_scale(system: HamiltonianSystem, z, t: float, theta) -> float:
    """The time over which the flow turns near ``z``: ``1 / rho(A)``, ``rho`` the spectral
    radius of ``A = df/dz`` (the linearised flow's fastest rate). Its eigenvalues do not change
    under any linear change of coordinates (units of each coordinate, an offset of the origin),
    so neither does this scale, which follows the units of time. Where ``A`` is nilpotent (a
    turning point at an inflection of the potential has no rate of its own) the rate is
    ``|A f| / |f|``, the rate at which the velocity turns; ``inf`` where ``f = 0``."""
    f, A = (np.asarray(value, float) for value in
            flow_jacobian_function(system)(np.asarray(z, float), t, theta))
    f = f.ravel()
    with np.errstate(all="ignore"):
        rate = float(np.max(np.abs(np.linalg.eigvals(A)))) if np.all(np.isfinite(A)) \
            else np.nan
        turning = float(np.linalg.norm(A @ f) / np.linalg.norm(f))
    # an eigenvalue at round-off of A's entries is the nilpotent case
    if not rate > 1e-6 * turning:
        rate = turning
    return 1.0 / rate if rate > 0 else np.inf


def symplectic_weights(system, z0, t0: float, theta) -> np.ndarray:
    """``W = (a_1 .. a_n, 1/a_1 .. 1/a_n)``: a norm ``|W dz|`` of a state's change that does not
    depend on the units of any coordinate or of time (the chaos indicators' tangent, the
    growth of an orbit's flow, ``exact/segments.py``). ``a_i = r_i^(-1/2)``
    with ``r_i`` the ratio of position to momentum the flow sets in degree of freedom ``i`` at
    the start: ``sqrt(|H_pp,ii| / |H_qq,ii|)`` (the oscillation's amplitude ratio), or
    ``T |H_pp,ii|`` where ``H`` is flat in ``q_i`` (``T`` the flow's time scale,
    `physics.hamiltonian.flow_time_scale`), or ``1 / (T |H_qq,ii|)`` where it is flat in
    ``p_i``. Each pair ``(q_i, p_i)`` is scaled by ``(a_i, 1/a_i)``, a symplectic map, so the
    exponents still pair. With the plain norm the fast Lyapunov indicator of a Henon-Heiles
    orbit was 2.76 in time units of 1 and 13.5 in time units of ``1e5`` (``ln 1e5`` more),
    its MEGNO 1.58 and 2.06."""
    n = system.n
    z0 = np.asarray(z0, float)
    _, A = flow_jacobian_function(system)(z0, t0, theta)
    A = np.asarray(A, float)
    mobility = np.abs(np.diagonal(A[:n, n:]))     # |H_pp,ii| = |dq_i'/dp_i|
    stiffness = np.abs(np.diagonal(A[n:, :n]))    # |H_qq,ii| = |dp_i'/dq_i|
    T = flow_time_scale(system, z0, t0, theta)
    ratio = np.ones(n)
    with np.errstate(all="ignore"):
        both = (mobility > 0) & (stiffness > 0)
        ratio[both] = np.sqrt(mobility[both] / stiffness[both])
        if np.isfinite(T) and T > 0:
            only_p = (mobility > 0) & ~(stiffness > 0)
            only_q = ~(mobility > 0) & (stiffness > 0)
            ratio[only_p] = T * mobility[only_p]
            ratio[only_q] = 1.0 / (T * stiffness[only_q])
    ratio = np.where(np.isfinite(ratio) & (ratio > 0), ratio, 1.0)
    a = 1.0 / np.sqrt(ratio)
    return np.concatenate([a, 1.0 / a])


def separable_parts(system: HamiltonianSystem):
    """``(T_p, V_q)`` as functions if ``H = T(p) + V(q, t)``, else a reason string.

    Read off the expression: ``H_p`` must not depend on ``q`` or ``t``, ``H_q`` not on ``p``.
    """
    H_p = ca.gradient(system.H, system.p)
    H_q = ca.gradient(system.H, system.q)
    if ca.depends_on(H_p, ca.vertcat(system.q, system.t)):
        return "dH/dp depends on q or t, so H is not T(p) + V(q, t)"
    if ca.depends_on(H_q, system.p):
        return "dH/dq depends on p, so H is not T(p) + V(q, t)"
    return (ca.Function("T_p", [system.p, system.theta], [H_p]),
            ca.Function("V_q", [system.q, system.t, system.theta], [H_q]))


def not_separable(system: HamiltonianSystem) -> str | None:
    """Why ``H`` is not ``T(p) + V(q, t)``, or ``None`` if it is (the ``applies`` of the methods
    that need a separable ``H``)."""
    parts = separable_parts(system)
    return parts if isinstance(parts, str) else None


def quadratic_kinetic_matrix(system: HamiltonianSystem):
    """``A(theta)`` if ``H = p.A p/2 + V(q, t)`` with ``A`` constant in ``q, p, t``, else a reason
    string. Lee's original scheme needs the Lagrangian ``v.A^{-1} v/2 - V``."""
    parts = separable_parts(system)
    if isinstance(parts, str):
        return parts
    H_p = ca.gradient(system.H, system.p)
    A = ca.jacobian(H_p, system.p)
    if ca.depends_on(A, ca.vertcat(system.q, system.p, system.t)):
        return "H is not quadratic in p (d2H/dp2 is not constant)"
    if ca.depends_on(ca.substitute(H_p, system.p, ca.DM.zeros(system.n)),
                     ca.vertcat(system.q, system.t)) or \
            not ca.is_equal(ca.simplify(ca.substitute(H_p, system.p, ca.DM.zeros(system.n))),
                            ca.SX.zeros(system.n), 2):
        return "H has a term linear in p"
    return A
