"""Linear stability of a periodic orbit: the discrete monodromy, its Floquet multipliers with
the trivial ones set apart, a stability index per nontrivial pair, and a verdict.

The discrete one-period map. At the prescribed energy ``E`` each step of the energy rule solves
the ``m = 2n + 1`` rows of its interval (``assembly.interval_rows``: the canonical equations
and ``H(Q_k, P_k) = E``) for ``(t_{k+1}, z_{k+1})`` given ``(t_k, z_k)``. By the implicit
function theorem, with ``G_a``, ``G_b`` the rows' Jacobians in ``(t_k, z_k)`` and
``(t_{k+1}, z_{k+1})`` (CasADi), the step's derivatives are ``-G_b^{-1} [G_a, G_u, G_E]``: in
the node, in the unfolding parameters ``u`` and in ``E``. Their product along the orbit gives
``M = dz_N/dz_0`` (the monodromy, ``2n x 2n``; the node times' dependence is inside, as
``t_{k+1}`` is solved with ``z_{k+1}``), ``dz_N/du`` and ``dz_N/dE``. At fixed ``E`` the step is
an outer billiard map about the level set ``H = E`` (the chord ``z_{k+1} - z_k`` along
``J grad H`` at its midpoint on the level set), a symplectic map (Tabachnikov): ``M`` is
symplectic and its multipliers come in pairs ``mu, 1/mu``.

The trivial multipliers. The exact monodromy fixes the flow direction and the generator
``J grad I_i`` of each symmetry ``I_i`` given (``integrals``); each fixed direction ``v`` comes
with a second multiplier 1 (the conserved quantity's direction, ``J v`` a left eigenvector).
The discrete map has the same structure: the symmetries are exact symmetries of the discrete
equations, and the discrete orbits at ``E`` form a one-parameter family in the section's value
``c`` (``orbit.py``'s phase condition), so ``v_0 = dz_0/dc`` is fixed by ``M``. ``v_0`` comes
from the orbit's own equations, condensed onto node 0: ``(M - I) v_0 + (dz_N/du) du = 0``,
``v_0[section] = 1``, ``g_i . v_0 = 0``, a square system that is the discrete orbit's Jacobian
with the interior nodes eliminated (nonsingular where the orbit is isolated at fixed ``E``).

The reduction. With ``V = [v_0, J grad I_1, ..., J grad I_r]`` (isotropic: its vectors
Poisson-commute), ``M`` maps the symplectic complement ``W = {w : V^T J w = 0}`` into itself
and fixes ``V``; in the orthonormal basis ``[V, C, D]`` (``C`` completing ``V`` in ``W``, ``D``
spanning ``W``'s orthogonal complement) ``M`` is block upper triangular::

    [[A_VV, *, *], [0, R, *], [0, 0, A_DD]]

The nontrivial multipliers are the eigenvalues of the reduced monodromy ``R`` (``2n - 2(r+1)``
square), the trivial ones those of ``A_VV`` and ``A_DD`` (both blocks are the identity for exact
fixed directions; how far they are from it is reported). A nontrivial pair crossing 1 (the
halo family's birth) is then still told apart from the trivial ones: they are never
eigenvalues of the same block. The exact monodromy is reduced
the same way with ``v_0 = f(z_0)``.

The stability index of a pair ``(mu, 1/mu)`` is ``k = mu + 1/mu``: real in ``(-2, 2)`` on the
unit circle, real beyond ``+-2`` for a real pair, complex for a quadruplet off both. The
indices are the roots of ``p(mu) = mu^m q(mu + 1/mu)`` for the characteristic polynomial ``p``
of ``R`` (palindromic), whose coefficients come from the traces of ``R, R^2, .., R^m``
(Newton's identities): symmetric functions of the multipliers, well conditioned where the
multipliers themselves are not (a double multiplier at a bifurcation). Verdict, with the
tolerance ``tol`` on the indices: ``stable`` when every index is real within ``tol`` and
``|k| < 2 - tol``; ``unstable`` when one is complex beyond ``tol`` or ``|k| > 2 + tol``;
``marginal`` otherwise (a pair at ``+-1`` within ``tol``: a bifurcation, or the trivial
structure of a one-degree-of-freedom orbit, which has no nontrivial pair and is ``stable``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from numpy.polynomial import chebyshev

from ...cache import cached
from ...discrete.scheme import Scheme
from ...errors import InputError
from ...physics.constraints import refuse_constrained
from ...solution import Solution
from ...validation import check_real
from ..exact.closure import ExactOrbit, close_exact, exact_field_directions
from .closed_grid import interval_rows
from .constrained_stability import constrained_monodromy
from .orbit import parse_section

VERDICTS = ("stable", "marginal", "unstable")
DEFAULT_TOL = 1e-6


def _step_derivative_function(system, scheme, integrals) -> ca.Function:
    """``(z_a, z_b, u, E, theta) -> (G_b, [G_a, G_u, G_E])``: the Jacobians of an interval's
    rows (``assembly.interval_rows``, the unfolding's metric ones) in the later node and in
    the rest."""
    def build():
        rows = interval_rows(system, scheme, integrals)
        z_a, z_b, u, level, _, theta = rows.sx_in()
        G = rows(z_a, z_b, u, level, ca.DM.ones(2 * system.n), theta)
        rest = ca.jacobian(G, ca.vertcat(z_a, u, level))
        return ca.Function("periodic_step_derivatives", [z_a, z_b, u, level, theta],
                           [ca.densify(ca.jacobian(G, z_b)), ca.densify(rest)])
    return cached(system, ("periodic_step_derivatives", scheme, tuple(integrals)), build)


@dataclass
class DiscreteMonodromy:
    """The derivatives of the discrete one-period map at the orbit (module docstring):
    ``monodromy = dz_N/dz_0`` (``2n x 2n``), ``unfolding = dz_N/du``, ``energy = dz_N/dE``, and
    the period's derivatives ``period_gradient = dT/d(z_0, u, E)``."""

    monodromy: np.ndarray
    unfolding: np.ndarray
    energy: np.ndarray
    period_gradient: np.ndarray


def discrete_monodromy(system, scheme, t, q, p, theta, energy: float,
                       integrals=()) -> DiscreteMonodromy:
    """The products of the step derivatives along the orbit's nodes ``t`` (``N + 1``), ``q``,
    ``p`` (the last node the first plus any whole turns), at ``u = 0``."""
    integrals = tuple(integrals)
    n, r, N = system.n, len(integrals), len(t) - 1
    m = 2 * n + 1
    z = np.column_stack([np.asarray(t, float) - t[0], q, p])
    G_b, G_rest = _step_derivative_function(system, scheme, integrals).map(N)(
        z[:-1].T, z[1:].T, np.zeros((1 + r, N)), np.full((1, N), energy), theta)
    G_b = np.asarray(G_b).reshape(m, N, m).transpose(1, 0, 2)          # (N, m rows, m)
    width = m + 1 + r + 1
    G_rest = np.asarray(G_rest).reshape(m, N, width).transpose(1, 0, 2)
    steps = -np.linalg.solve(G_b, G_rest)                               # (N, m, width)
    # sensitivity of (t_k, z_k) to (z_0, u, E); t_0 is fixed
    S = np.zeros((m, 2 * n + 1 + r + 1))
    S[1:, :2 * n] = np.eye(2 * n)
    for k in range(N):
        A = steps[k]
        S = A[:, :m] @ S + np.hstack([np.zeros((m, 2 * n)), A[:, m:]])
    return DiscreteMonodromy(monodromy=S[1:, :2 * n], unfolding=S[1:, 2 * n:2 * n + 1 + r],
                             energy=S[1:, -1], period_gradient=S[0])


def section_direction(monodromy: DiscreteMonodromy, section_index: int,
                      generators: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(v_0, du)``: the derivative of the discrete orbit's node 0 and unfolding parameters in
    the section's value, from the condensed equations (module docstring)."""
    k, rows = _bordered(monodromy, section_index, generators)
    rhs = np.zeros(rows.shape[0])
    rhs[k] = 1.0
    solution = np.linalg.solve(rows, rhs)
    return solution[:k], solution[k:]


def _bordered(monodromy: DiscreteMonodromy, section_index: int, generators: np.ndarray):
    """``(k, A)``: the condensed orbit equations' matrix ``[M - I, B]`` bordered by the
    section's row and the phase conditions' rows (``k`` the size of the state)."""
    M, B = monodromy.monodromy, monodromy.unfolding
    k, u = M.shape[0], B.shape[1]
    r = generators.shape[0]
    section = np.zeros(k)
    section[section_index - 1] = 1.0
    return k, np.vstack([np.hstack([M - np.eye(k), B]), np.r_[section, np.zeros(u)],
                         np.hstack([generators, np.zeros((r, u))])])


def _symplectic_form(k: int) -> np.ndarray:
    n = k // 2
    return np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])


def _orthonormal(columns: np.ndarray, rank: int) -> np.ndarray:
    U, _, _ = np.linalg.svd(columns, full_matrices=False)
    return U[:, :rank]


def _null_space(rows: np.ndarray, dimension: int) -> np.ndarray:
    """An orthonormal basis of the ``dimension`` right singular vectors of ``rows`` with the
    smallest singular values."""
    _, _, Vt = np.linalg.svd(rows)
    return Vt[Vt.shape[0] - dimension:].T


def reduce(M: np.ndarray, fixed: np.ndarray):
    """``(R, trivial, trivial_error, defect, isotropy)`` for ``M`` and its fixed directions
    ``V`` (module docstring): the reduced monodromy; the eigenvalues of ``A_VV`` and ``A_DD``;
    the largest entry of ``A_VV - I`` and ``A_DD - I`` relative to ``max(1, |M|)`` (both
    blocks are the identity for exact fixed directions, in the orthonormal basis: this is the
    backward error of "the trivial multipliers are 1", in the units of ``M``'s round-off,
    which the discrete map's twist makes large: ``|M|`` grows like ``N^2``; the blocks'
    eigenvalues, Jordan-like, move by about the square root of the absolute error); the
    largest entry of the blocks below them, which vanish too (relative to ``|M|``); and the
    largest ``|v_i^T J v_j|``."""
    k, f = M.shape[0], fixed.shape[1]
    J = _symplectic_form(k)
    V = _orthonormal(fixed, f)
    D = _orthonormal(J @ V, f)
    C = _null_space(np.vstack([V.T @ J, V.T]), k - 2 * f)
    B = np.hstack([V, C, D])
    A = B.T @ M @ B
    R = A[f:k - f, f:k - f]
    blocks = (A[:f, :f], A[k - f:, k - f:])
    trivial = np.concatenate([np.linalg.eigvals(block) for block in blocks])
    scale = max(np.linalg.norm(M, 2), 1.0)
    trivial_error = max(float(np.max(np.abs(block - np.eye(f)))) for block in blocks) / scale
    defect = max(float(np.max(np.abs(A[f:, :f]), initial=0.0)),
                 float(np.max(np.abs(A[k - f:, :k - f]), initial=0.0))) / scale
    isotropy = float(np.max(np.abs(V.T @ J @ V), initial=0.0))
    return R, trivial, trivial_error, defect, isotropy


def stability_indices(R: np.ndarray) -> np.ndarray:
    """The roots ``k_j`` of ``q`` with ``det(mu I - R) = mu^m q(mu + 1/mu)`` (module
    docstring), sorted by real part; empty for an empty ``R``."""
    size = R.shape[0]
    m = size // 2
    if m == 0:
        return np.zeros(0, complex)
    traces, power = [], np.eye(size)
    for _ in range(m):
        power = power @ R
        traces.append(np.trace(power))
    e = [1.0]  # elementary symmetric functions of the multipliers, by Newton's identities
    for j in range(1, m + 1):
        e.append(sum((-1) ** (i - 1) * e[j - i] * traces[i - 1] for i in range(1, j + 1)) / j)
    a = [(-1) ** j * e[j] for j in range(m + 1)]  # p(mu) = sum_j a_j mu^(2m - j), a palindrome
    # mu^-m p(mu) = a_m + sum_j a_(m-j) (mu^j + mu^-j), mu^j + mu^-j = 2 T_j((mu + 1/mu)/2)
    coefficients = [a[m]] + [2 * a[m - j] for j in range(1, m + 1)]
    roots = 2 * chebyshev.chebroots(coefficients)
    return np.array(sorted(np.asarray(roots, complex), key=lambda x: (x.real, x.imag)))


def verdict(indices: np.ndarray, tol: float) -> str:
    """``stable``, ``marginal`` or ``unstable`` from the indices (module docstring)."""
    if indices.size == 0:
        return "stable"
    if np.any(np.abs(indices.imag) > tol) or np.any(np.abs(indices.real) > 2 + tol):
        return "unstable"
    if np.all(np.abs(indices.real) < 2 - tol):
        return "stable"
    return "marginal"


@dataclass
class Stability:
    """The linear stability of one periodic orbit (module docstring).

    Attributes:
        multipliers: the nontrivial Floquet multipliers (eigenvalues of the reduced monodromy,
            ``2n - 2(r + 1)`` of them), by modulus.
        indices: one stability index ``mu + 1/mu`` per nontrivial pair.
        verdict: ``stable``, ``marginal`` or ``unstable`` with tolerance ``tol`` on the indices.
        trivial: the trivial multipliers (``2(r + 1)``): the eigenvalues of the blocks of the
            fixed directions and of their dual, 1 in exact arithmetic.
        trivial_error: the largest entry of those blocks minus the identity, relative to
            ``max(1, |M|)`` (`reduce`): how far "the trivial multipliers are 1" is from
            holding, in the units of ``M``'s round-off.
        defect: the largest entry of the blocks that vanish for exact fixed directions, relative
            to ``|M|`` (round-off, or the exponentially small defect of the discrete orbit).
        isotropy: the largest ``|v_i^T J v_j|`` of the fixed directions (0 for commuting
            symmetries; total momentum 0 makes translations commute with rotation).
        monodromy: ``M`` (``2n x 2n``); ``reduced``: ``R``.
        fixed: the fixed directions ``V`` as columns.
        kind: ``"discrete"`` or ``"exact"``.
        extra: further numbers (``period_derivative`` dT/dE of the discrete orbit, ...).
        exact: the exact flow's `Stability` at the exact orbit near this one (``None``
            unless asked for: `periodic_stability`).
        exact_orbit: that exact orbit (``exact.ExactOrbit``: its closure, its distance).
    """

    multipliers: np.ndarray
    indices: np.ndarray
    verdict: str
    tol: float
    trivial: np.ndarray
    trivial_error: float
    defect: float
    isotropy: float
    monodromy: np.ndarray
    reduced: np.ndarray
    fixed: np.ndarray
    kind: str
    extra: dict = field(default_factory=dict)
    exact: Stability | None = None
    exact_orbit: ExactOrbit | None = None

    @property
    def index_error(self) -> float | None:
        """The largest ``|k_j - k_j(exact)| / max(2, |k_j(exact)|)`` of the indices (sorted
        alike: an unstable pair's index grows like its multiplier, a stable one's lies in
        ``[-2, 2]``), or ``None``."""
        if self.exact is None or self.exact.indices.size != self.indices.size:
            return None
        scale = np.maximum(2.0, np.abs(self.exact.indices))
        return float(np.max(np.abs(self.indices - self.exact.indices) / scale, initial=0.0))

    def summary(self) -> str:
        """One line: the verdict, the indices, the trivial multipliers' distance from 1 and,
        if made, the exact flow's verdict and the indices' difference."""
        shown = ", ".join(_shown(k) for k in self.indices) or "none (every multiplier is trivial)"
        text = (f"{self.verdict} (tolerance {self.tol:g} on the indices): stability indices "
                f"{shown}; {self.trivial.size} trivial multipliers, their blocks the identity "
                f"to {self.trivial_error:.1e} of |M|")
        if self.exact is not None:
            closed = self.exact_orbit
            text += (f"; exact flow: {self.exact.verdict}"
                     + (f", indices differ by {self.index_error:.2e} (relative)"
                        if self.index_error is not None else "")
                     + (f", orbit closed to {closed.closure:.1e} at {closed.distance:.2e} from "
                        f"node 0" if closed is not None else ""))
        return text

    def as_dict(self) -> dict:
        """Plain values for a run folder's ``stability.json`` (complex numbers as pairs)."""
        def pairs(values):
            return [[float(v.real), float(v.imag)] for v in np.asarray(values, complex)]
        return {"kind": self.kind, "verdict": self.verdict, "tol": self.tol,
                "multipliers": pairs(self.multipliers), "indices": pairs(self.indices),
                "moduli": [float(abs(v)) for v in self.multipliers],
                "trivial": pairs(self.trivial), "trivial_error": self.trivial_error,
                "defect": self.defect, "isotropy": self.isotropy, **self.extra,
                "exact": None if self.exact is None else self.exact.as_dict(),
                "exact_orbit": None if self.exact_orbit is None else self.exact_orbit.as_dict(),
                "index_error": self.index_error}


def _shown(k: complex) -> str:
    return f"{k.real:.8g}" if k.imag == 0 else f"{k.real:.6g}{k.imag:+.3g}i"


def analyse(M: np.ndarray, fixed: np.ndarray, *, tol: float, kind: str,
            extra: dict | None = None) -> Stability:
    """Reduce ``M`` by its fixed directions and judge the nontrivial pairs."""
    R, trivial, trivial_error, defect, isotropy = reduce(M, fixed)
    indices = stability_indices(R)
    multipliers = np.linalg.eigvals(R) if R.size else np.zeros(0, complex)
    multipliers = np.array(sorted(np.asarray(multipliers, complex),
                                  key=lambda x: (abs(x), np.angle(x))))
    return Stability(multipliers=multipliers, indices=indices, verdict=verdict(indices, tol),
                     tol=tol, trivial=trivial, trivial_error=trivial_error,
                     defect=defect, isotropy=isotropy, monodromy=M, reduced=R, fixed=fixed,
                     kind=kind, extra=dict(extra or {}))


def generator_rows(system, theta, z0, integrals) -> np.ndarray:
    """``J grad I_i(z_0)`` as rows (``r x 2n``)."""
    if not integrals:
        return np.zeros((0, 2 * system.n))
    return exact_field_directions(system, theta, z0, integrals)[:, 1:].T


def orbit_stability(system, solution: Solution, *, params=None, integrals=(),
                    tol: float = DEFAULT_TOL) -> Stability:
    """The stability of a periodic orbit that `solve_periodic` returned (module
    docstring): its discrete monodromy, reduced by ``v_0 = dz_0/dc`` and the generators of
    ``integrals`` (the same ones the orbit was solved with).

    Args:
        system: the system the orbit was solved for.
        solution: the orbit (its ``orbit`` gives the energy and the section).
        params: the system's parameter values.
        integrals: the first integrals given to ``solve_periodic``.
        tol: the tolerance on the stability indices for the verdict.

    Returns:
        A `Stability`; ``extra`` holds ``period_derivative`` (``dT/dE`` along the
        discrete family at this ``N``), ``section_unfolding`` (``du/dc``, zero up to the
        discrete orbit's defect) and ``monodromy_norm``.
    """
    refuse_constrained(system, "orbit_stability")  # the discrete map is the unconstrained one
    tol = check_real("tol", tol, positive=True)
    if not isinstance(solution, Solution) or solution.orbit is None:
        raise InputError("solution must be a periodic orbit returned by solve_periodic")
    integrals = tuple(integrals)
    solved_with = len(solution.orbit.integral_unfoldings)
    if len(integrals) != solved_with:
        raise InputError(f"integrals: the orbit was solved with {solved_with} integrals, got "
                         f"{len(integrals)}")
    index, _, _ = parse_section(solution.orbit.section, system.n)
    return discrete_stability(system, Scheme.coerce(solution.scheme), solution.t, solution.q,
                              solution.p, energy=float(solution.orbit.energy),
                              section_index=index, theta=system.parameter_vector(params),
                              integrals=integrals, tol=tol)


def periodic_stability(system, orbit: Solution, *, params=None, integrals=(),
                       tol: float = DEFAULT_TOL, exact: bool = True) -> Stability:
    """The Floquet multipliers of a periodic orbit and its verdict (module docstring), checked
    against the exact flow.

    The discrete orbit's monodromy (the step maps' derivatives, node times included, multiplied
    along the orbit) is reduced by its trivial directions; the nontrivial multipliers give one
    stability index per pair and the verdict. With ``exact``, the exact periodic orbit near
    this one is found by shooting on the exact flow (``exact/closure.py``: variational
    equations at ``rtol = 1e-12``, on segments cut where the flow grows, started from this
    orbit's nodes) and its monodromy analysed the same way: the indices' difference is the
    discretisation error of the multipliers (``O(N^-2)``), and an exact orbit that does not
    close says the discrete one is not near an orbit of the flow.

    Args:
        system: the system the orbit was solved for.
        orbit: a periodic orbit returned by `solve_periodic` (a failed one is
            refused).
        params: the system's parameter values (those of the solve).
        integrals: the first integrals the orbit was solved with.
        tol: the tolerance on the stability indices: ``|k| = 2`` within it is ``marginal``.
        exact: also close the exact flow and analyse its monodromy.

    Returns:
        A `Stability`: ``multipliers``, ``indices``, ``verdict``, ``trivial`` and,
        with ``exact``, ``exact`` and ``exact_orbit``; ``summary()`` says it in one line.
    """
    if getattr(system, "n_constraints", 0):  # on the constrained exact flow
        M, fixed, extra = constrained_monodromy(system, orbit, params=params,
                                                integrals=integrals)
        return analyse(M, fixed, tol=check_real("tol", tol, positive=True), kind="exact",
                       extra=extra)
    if isinstance(orbit, Solution) and not orbit.success:
        raise InputError(f"orbit: a failed solve has no monodromy to trust ({orbit.status.code}:"
                         f" {orbit.message[:120]})")
    stability = orbit_stability(system, orbit, params=params, integrals=integrals, tol=tol)
    if exact:
        theta = system.parameter_vector(params)
        index, value, _ = parse_section(orbit.orbit.section, system.n)
        shift = np.concatenate([2 * np.pi * np.asarray(orbit.orbit.winding, float),
                                np.zeros(system.n)])
        closed = close_exact(system, theta, np.concatenate([orbit.q[0], orbit.p[0]]),
                             float(orbit.orbit.period), energy=float(orbit.orbit.energy),
                             section_index=index, section_value=value,
                             integrals=tuple(integrals), shift=shift,
                             path=(orbit.t, np.hstack([orbit.q, orbit.p])))
        stability.exact_orbit = closed
        if closed.converged:
            stability.exact = exact_stability(system, theta, closed.z0, closed.monodromy,
                                              integrals=integrals, tol=tol)
    return stability


def discrete_stability(system, scheme, t, q, p, *, energy: float, section_index: int, theta,
                       integrals=(), tol: float = DEFAULT_TOL) -> Stability:
    """`orbit_stability` on the nodes of a discrete orbit (``t``, ``q``, ``p``: ``N + 1``
    rows) at ``energy``, whose phase condition fixes ``z_0[section_index - 1]``."""
    integrals = tuple(integrals)
    discrete = discrete_monodromy(system, scheme, t, q, p, theta, energy, integrals)
    z0 = np.concatenate([q[0], p[0]])
    generators = generator_rows(system, theta, z0, integrals)
    v0, du = section_direction(discrete, section_index, generators)
    fixed = np.column_stack([v0, generators.T]) if integrals else v0[:, None]
    _, period_derivative = energy_direction(discrete, section_index, generators)
    return analyse(discrete.monodromy, fixed, tol=tol, kind="discrete",
                   extra={"period_derivative": period_derivative,
                          "section_unfolding": float(np.max(np.abs(du))),
                          "monodromy_norm": float(np.linalg.norm(discrete.monodromy, 2))})


def energy_direction(monodromy: DiscreteMonodromy, section_index: int, generators):
    """``(dz_0/dE, dT/dE)`` along the discrete family at fixed section and phase conditions."""
    k, rows = _bordered(monodromy, section_index, generators)
    rhs = np.concatenate([-monodromy.energy, np.zeros(rows.shape[0] - k)])
    solution = np.linalg.solve(rows, rhs)
    dT = float(monodromy.period_gradient @ np.concatenate([solution, [1.0]]))
    return solution[:k], dT


def exact_stability(system, theta, z0, monodromy: np.ndarray, *, integrals=(),
                    tol: float = DEFAULT_TOL) -> Stability:
    """The same analysis of the exact flow's monodromy at ``z_0`` (fixed directions ``f(z_0)``
    and the generators)."""
    fixed = exact_field_directions(system, theta, z0, tuple(integrals))
    return analyse(monodromy, fixed, tol=tol, kind="exact")



