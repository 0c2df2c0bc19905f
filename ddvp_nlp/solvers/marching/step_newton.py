"""Newton's method on one march step: the option set both paths share, the careful solve,
and the compiled path's unrolled ``fast_newton``.

Both paths solve the same step equations (``steps.py``) with the same options
(`NEWTON_OPTIONS`) and accept a root by the same test (``acceptance.py``):

- the careful path (`NewtonSteps`): CasADi's ``newton`` rootfinder from the Runge-Kutta
  predictor, retried from other guesses of ``tau`` (`RETRY_FACTORS`), each outcome in a
  `StepResult`;
- the compiled path (``chunk.py``): CasADi's ``fast_newton``, which can be code-generated, with
  its first iterations written out as straight-line code (`unrolled_newton`, below).

The unrolled ``fast_newton``. ``fast_newton`` iterates, at most ``max_iter`` times:
evaluate ``g(x)`` and ``J = dg/dx``; stop if ``|g|_inf <= abstol``; else factor ``J = QR``
(Householder, CasADi's sparse ``casadi_qr``), ``dx = J^-1 g``, ``x <- x - dx``; stop if
``|dx|_inf <= abstol_step``. Its loop and its generic sparse QR cost more than the arithmetic of
a small step. `unrolled_newton` writes the first ``iterations`` of that loop as one SX
expression: the same Jacobian function, the same QR in the same order of operations (specialised
to the Jacobian's sparsity pattern), each update masked once the loop would have stopped. It
returns the iterate and whether the loop would have stopped; where it would not, the caller
goes on with ``fast_newton`` from that iterate, so the result is the one ``fast_newton`` gives,
to the last bit (the chunk compiles with ``-ffp-contract=off``).

The march's chunk asks for a cheaper linear solve on small systems (``linear="lu"``,
`DenseLU`): the same iterations and tests, each update by elimination, and where the unrolled
iterations did not stop, `chain_newton`'s loop goes on in place of ``fast_newton``; the result
is then ``fast_newton``'s root to round-off, not its bits.

One test differs from ``fast_newton``'s everywhere: an update is small when it is below
``abstolStep`` *or* within a few units of round-off of the iterate (`small_update`,
`ROUNDOFF_STEPS`). For iterates below 11.3 in size this is ``fast_newton``'s test to the bit;
above, ``fast_newton``'s absolute test cannot pass and ran every step to ``max_iter``.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import casadi as ca
import numpy as np

from ...cache import cached
from ...errors import InputError
from ...solution import Status
from .chain_newton import chain_newton, norm_inf, small_update
from .steps import EnergyCheck, FixedCheck, StepFunctions, step_functions

# The options of both paths' rootfinders (``newton`` careful, ``fast_newton`` compiled).
# error_on_fail: on the virtual machine fast_newton raises by default; compiled, it cannot.
# Either way a step that did not converge fails its residual check and is redone carefully.
# show_eval_warnings off: a trial point where the residual or its Jacobian is not finite is a
# failed step the march reports in its own words, not CasADi's "NaN detected ...
# oracle_function.cpp" line on stderr (issue 40)
NEWTON_OPTIONS = MappingProxyType({"abstol": 1e-14, "abstolStep": 1e-14, "max_iter": 30,
                                   "error_on_fail": False, "show_eval_warnings": False})
# Starting guesses for tau, as multiples of the previous step, tried in order when Newton from the
# predictor fails or lands on tau <= 0. The spurious root sits at -tau_{k-1}; these start far
# from it.
RETRY_FACTORS = (1.0, 0.5, 2.0, 0.25)
# Newton updates the careful path adds to a root whose residuals fail the acceptance test
# (`NewtonSteps._polish`)
POLISH_UPDATES = 3


def careful_rootfinder(name: str, residual: ca.Function, system, scheme) -> ca.Function:
    """CasADi's Newton rootfinder on ``residual``; a step whose equations cannot determine it
    (a structurally singular Jacobian, for example ``H = p[0]`` or a constant ``H`` under an
    energy rule, whose energy equation does not depend on the step) is refused by name."""
    rows = residual.size1_out(0)
    rank = residual.sparsity_jac(0, 0)
    if ca.sprank(rank) < rows:
        unknowns = "(z_next, tau)" if name == "energy_step" else "z_next"
        raise InputError(
            f"H of {system.name!r} has no well-posed {scheme.rule} step: the step equations do "
            f"not determine {unknowns} (their Jacobian is structurally singular: rank "
            f"{ca.sprank(rank)} of {rows}). Under an energy rule the energy of an interval must "
            "depend on its length, which it does not for H linear in p or constant; use "
            "--scheme fixed" if name == "energy_step" else
            f"H of {system.name!r} has no well-posed step: the canonical equations do not "
            f"determine z_next (rank {ca.sprank(rank)} of {rows})")
    return ca.rootfinder(name, "newton", residual, dict(NEWTON_OPTIONS))

def rootfinders(system, scheme, functions: StepFunctions) -> tuple:
    """The careful path's rootfinders ``(fixed, energy)`` of ``functions`` (``energy`` is
    ``None`` for the ``fixed`` rule), built once per system and scheme."""
    def build():
        fixed = careful_rootfinder("fixed_step", functions.fixed_newton_residual, system,
                                   scheme)
        energy = (careful_rootfinder("energy_step", functions.energy_newton_residual, system,
                                     scheme)
                  if scheme.variable_steps else None)
        return fixed, energy
    return cached(system, ("march_roots", scheme), build)


@dataclass
class StepResult:
    """One careful step: the new node, or a failure status with a detail in words.

    The new node is ``(t_next, z_next)``; ``tau`` is the length an energy step solved for.
    ``energy`` is the energy residual of an accepted energy step (it joins the drift);
    ``H_node``, ``w_node`` are the monitors' values at the new node."""

    status: Status
    detail: str = ""
    t_next: float | None = None
    z_next: np.ndarray | None = None
    tau: float | None = None
    energy: float = 0.0
    H_node: float = 0.0
    w_node: float = 0.0

    @classmethod
    def failed(cls, status: Status, detail: str = "") -> StepResult:
        return cls(status, detail)


class StepProblem:
    """One march step as a problem: ``F(x; old nodes, theta) = 0`` for the new unknowns ``x``,
    with its Jacobians in ``x``, in the old nodes and in ``theta``, from the same CasADi
    expressions the march's Newton solves (``steps.StepFunctions``).

    ``kind="fixed"``: ``x = z_b``, old node ``z_a``, ``w = [t_a, t_b, z_a, theta]``;
    ``kind="energy"``: ``x = [z_{k+1}, tau_k]``, old nodes ``(z_{k-1}, z_k)``,
    ``w = [t_{k-1}, t_k, z_{k-1}, z_k, theta, drift]`` (energy rules only). The march does not
    use this object: it is where a forward sensitivity ``dz_{k+1}/dtheta = -F_x^-1 (F_old
    dz_old/dtheta + F_theta)`` or an adjoint sweep ``F_x^T lambda_k = ...`` takes its
    Jacobians from."""

    def __init__(self, system, scheme, theta, kind: str = "fixed"):
        if kind not in ("fixed", "energy"):
            raise InputError(f"kind must be 'fixed' or 'energy', not {kind!r}")
        if kind == "energy" and not scheme.variable_steps:
            raise InputError(f"scheme {scheme.rule!r} has no energy step")
        functions = step_functions(system, scheme)
        self.kind = kind
        self.theta = np.asarray(theta, float).ravel()
        self._residual = functions.fixed_residual if kind == "fixed" else \
            functions.energy_residual
        n = system.n
        old = 2 * n if kind == "fixed" else 4 * n
        self._old = slice(2, 2 + old)
        self._parameters = slice(2 + old, 2 + old + self.theta.size)
        self._jacobians = step_jacobian_function(system, scheme, kind)

    def parameters(self, times, old_nodes, drift: float = 0.0) -> np.ndarray:
        """``w`` from the old times ``(t_a, t_b)`` or ``(t_{k-1}, t_k)``, the old node values
        (``z_a``, or ``(z_{k-1}, z_k)``) and, for an energy step, the drift."""
        values = [np.ravel(times), *(np.ravel(z) for z in np.atleast_2d(old_nodes)),
                  self.theta]
        return np.concatenate(values + ([[drift]] if self.kind == "energy" else []))

    def residual(self, x, w) -> np.ndarray:
        """``F(x; w)``."""
        return np.asarray(self._residual(x, w)).ravel()

    def jacobians(self, x, w):
        """``(dF/dx, dF/d old nodes, dF/dtheta)`` as dense arrays."""
        in_x, in_w = (np.asarray(J) for J in self._jacobians(x, w))
        return in_x, in_w[:, self._old], in_w[:, self._parameters]

    def solve(self, x, w, rhs) -> np.ndarray:
        """``(dF/dx)^-1 rhs`` at ``(x, w)``."""
        return _lu_solve(self.jacobians(x, w)[0], rhs, 0)

    def solve_transposed(self, x, w, rhs) -> np.ndarray:
        """``(dF/dx)^-T rhs`` at ``(x, w)``, beside `solve` (one step of an adjoint sweep)."""
        return _lu_solve(self.jacobians(x, w)[0], rhs, 1)

    def sensitivity(self, x, w) -> tuple:
        """``(dx/d old nodes, dx/dtheta)`` of the step's root ``x``: ``-(dF/dx)^-1 dF/d(old,
        theta)`` (the implicit function theorem; valid at a root)."""
        in_x, in_old, in_theta = self.jacobians(x, w)
        solved = _lu_solve(in_x, np.hstack([in_old, in_theta]), 0)
        return -solved[:, :in_old.shape[1]], -solved[:, in_old.shape[1]:]


def step_jacobian_function(system, scheme, kind: str) -> ca.Function:
    """``(x, w) -> (dF/dx, dF/dw)`` (dense) of the step residual of ``kind`` (``"fixed"`` or
    ``"energy"``, `StepProblem`), built once per system and scheme: what `StepProblem` and the
    march's derivatives (``derivatives.py``) differentiate."""
    def build():
        functions = step_functions(system, scheme)
        residual = functions.fixed_residual if kind == "fixed" else functions.energy_residual
        x, w = residual.sx_in()
        F = residual.call([x, w])[0]
        return ca.Function(f"{kind}_step_jacobians", [x, w], [
            ca.densify(ca.jacobian(F, x)), ca.densify(ca.jacobian(F, w))])
    return cached(system, ("march_step_jacobians", scheme, kind), build)


def _lu_solve(matrix: np.ndarray, rhs: np.ndarray, trans: int) -> np.ndarray:
    """``matrix^-1 rhs`` (``trans=1``: ``matrix^-T rhs``) from one LAPACK LU; ``scipy.linalg``
    is imported here, so that a march that never asks loads none of it
    (tests/architecture/test_import_cost.py)."""
    import scipy.linalg
    return scipy.linalg.lu_solve(scipy.linalg.lu_factor(matrix), rhs, trans=trans)


class NewtonSteps:
    """Careful steps: CasADi's ``newton`` on `StepFunctions`, checked by ``acceptance``
    (an `Acceptance`). Counts Newton iterations and
    retries."""

    def __init__(self, system, scheme, functions: StepFunctions, theta: np.ndarray, acceptance):
        self.system, self.scheme = system, scheme
        self.functions = functions
        self.fixed_root, self.energy_root = rootfinders(system, scheme, functions)
        self.theta = theta
        self.acceptance = acceptance
        self.newton_iterations = 0
        self.retries = 0

    def _solve(self, root, guess, w):
        x = np.asarray(root(guess, w)).ravel()
        stats = root.stats()
        self.newton_iterations += int(stats.get("iter_count", 0))
        # Read return_status: CasADi's "success" flag was seen False on converged calls.
        return x, stats.get("return_status") == "success"

    def fixed_step(self, t_a: float, t_b: float, z_a: np.ndarray) -> StepResult:
        """``z_b`` on ``[t_a, t_b]`` from the RK4 predictor."""
        f = self.functions
        w = np.concatenate([[t_a, t_b], z_a, self.theta])
        z_b, converged = self._solve(self.fixed_root, f.fixed_predict(w), w)
        if not np.all(np.isfinite(z_b)):
            return StepResult.failed(Status.NON_FINITE, f"z = {z_b.tolist()}")
        check = FixedCheck(*(float(v) for v in f.fixed_check(z_b, w)))
        # The residual test decides, as on the compiled path: CasADi's newton stops at an
        # absolute 1e-14, which a state of size 1e4 cannot reach in double precision (a motion
        # in other units failed its first step where the same motion in units of 1 marched).
        if converged and not self.acceptance.residuals_ok(check.canonical, check.size):
            z_b = self._polish("fixed", z_b, w)
            check = FixedCheck(*(float(v) for v in f.fixed_check(z_b, w)))
        if not self.acceptance.residuals_ok(check.canonical, check.size):
            if not converged:
                return StepResult.failed(Status.NEWTON_FAILED)
            return StepResult.failed(Status.RESIDUAL_TOO_LARGE,
                                     self.acceptance.residuals_refused(
                                         check.canonical, check.size))
        return StepResult(Status.SUCCESS, t_next=t_b, z_next=z_b, H_node=check.H_node,
                          w_node=check.w_node)

    def energy_parameters(self, t_prev, t_mid, z_prev, z_mid, drift) -> np.ndarray:
        """The parameter vector ``w`` of the energy step functions."""
        return np.concatenate([[t_prev, t_mid], z_prev, z_mid, self.theta, [drift]])

    def energy_step(self, t_prev, t_mid, z_prev, z_mid, drift) -> StepResult:
        """``(z_{k+1}, tau_k)``: Newton from the predictor with ``tau = f tau_{k-1}`` for each
        ``f`` in ``RETRY_FACTORS`` until a root passes every check. On failure the status says
        how the worst attempt failed (a residual above the tolerance over a negative step over
        Newton's failure)."""
        f = self.functions
        w = self.energy_parameters(t_prev, t_mid, z_prev, z_mid, drift)
        tau_prev = t_mid - t_prev
        detail = ""
        worst = Status.NEWTON_FAILED
        for attempt, factor in enumerate(RETRY_FACTORS):
            if attempt:
                self.retries += 1
            x, converged = self._solve(self.energy_root, f.energy_predict(w, factor * tau_prev), w)
            if not np.all(np.isfinite(x)):
                worst, detail = Status.NON_FINITE, f"(z, tau) = {x.tolist()}"
                continue
            if not converged and not self._passes(x, w):
                continue
            tau = x[-1]
            if tau <= 0:
                if worst is not Status.RESIDUAL_TOO_LARGE:
                    worst, detail = Status.NO_ADMISSIBLE_STEP, f"Newton found tau = {tau:.6g}"
                continue
            check = EnergyCheck(*(float(v) for v in f.energy_check(x, w)))
            if not self.acceptance.residuals_ok(check.canonical, check.size, check.energy,
                                                check.H_interval):
                polished = self._polish("energy", x, w)
                if polished[-1] > 0:
                    x, tau = polished, polished[-1]
                    check = EnergyCheck(*(float(v) for v in f.energy_check(x, w)))
            if not self.acceptance.residuals_ok(check.canonical, check.size, check.energy,
                                                check.H_interval):
                worst, detail = Status.RESIDUAL_TOO_LARGE, self.acceptance.residuals_refused(
                    check.canonical, check.size, check.energy, check.H_interval)
                continue
            return StepResult(Status.SUCCESS, t_next=t_mid + tau, z_next=x[:-1], tau=tau,
                              energy=check.energy, H_node=check.H_node, w_node=check.w_node)
        return StepResult.failed(worst, detail)

    def _polish(self, kind: str, x: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Up to ``POLISH_UPDATES`` Newton updates of ``x`` on the step's unscaled rows, for a
        root CasADi's ``newton`` returned whose residuals fail the acceptance test: it stops
        once an update is below an absolute 1e-14 without applying it, so at a node far below
        the units (1e-10) the returned ``x`` can be its first guess. Stops early once the rows
        stop shrinking; the acceptance test then decides as before."""
        residual = (self.functions.fixed_residual if kind == "fixed"
                    else self.functions.energy_residual)
        jacobian = step_jacobian_function(self.system, self.scheme, kind)
        rows = np.asarray(residual(x, w)).ravel()
        for _ in range(POLISH_UPDATES):
            try:
                moved = x - np.linalg.solve(np.asarray(jacobian(x, w)[0]), rows)
            except np.linalg.LinAlgError:
                break
            moved_rows = np.asarray(residual(moved, w)).ravel()
            if not (np.all(np.isfinite(moved))
                    and np.max(np.abs(moved_rows)) < np.max(np.abs(rows))):
                break
            self.newton_iterations += 1
            x, rows = moved, moved_rows
        return x

    def _passes(self, x, w) -> bool:
        """Whether an energy step Newton did not call converged passes the residual test with
        a positive step, the compiled path's test (see `fixed_step`)."""
        if not x[-1] > 0:
            return False
        check = EnergyCheck(*(float(v) for v in self.functions.energy_check(x, w)))
        return bool(self.acceptance.residuals_ok(check.canonical, check.size, check.energy,
                                                 check.H_interval))


# --- the compiled path: fast_newton unrolled --------------------------------------------------

def _reflect(x: list, nz_v: list, rows: list, entries: range, beta) -> None:
    """``x -= beta (v . x) v`` for the Householder vector ``v`` stored in ``nz_v[entries]`` at
    rows ``rows[entries]`` (in place), in ``casadi_qr``'s order of operations."""
    alpha = ca.SX(0)
    for k in entries:
        alpha = alpha + nz_v[k] * x[rows[k]]
    alpha = alpha * beta
    for k in entries:
        x[rows[k]] = x[rows[k]] - alpha * nz_v[k]


def _house(v: list, count: int):
    """``casadi_house`` on ``v[:count]`` (in place): returns ``(s, beta)``."""
    v0 = v[0]
    sigma = ca.SX(0)
    for i in range(1, count):
        sigma = sigma + v[i] * v[i]
    s = ca.sqrt(v0 * v0 + sigma)
    sigma_is_zero = sigma == 0
    v0_nonpos = v0 <= 0
    v[0] = ca.if_else(sigma_is_zero, 1, ca.if_else(v0_nonpos, v0 - s, -sigma / (v0 + s)))
    beta = ca.if_else(sigma_is_zero, 2 * v0_nonpos, -1 / (s * v[0]))
    return s, beta


class SparseQR:
    """``casadi_qr`` and ``casadi_qr_solve`` for one sparsity pattern, on SX scalars."""

    def __init__(self, pattern: ca.Sparsity):
        self.pattern = pattern
        sp_v, sp_r, self.prinv, self.pc = pattern.qr_sparse(True)
        self.nrow = sp_v.size1()
        self.ncol = pattern.size2()
        self.a_colind, self.a_row = pattern.colind(), pattern.row()
        self.v_colind, self.v_row = sp_v.colind(), sp_v.row()
        self.r_colind, self.r_row = sp_r.colind(), sp_r.row()

    def factor(self, nz_a: list):
        """The nonzeros of ``V``, ``R`` and ``beta`` of ``A`` (its nonzeros ``nz_a``)."""
        x = [ca.SX(0)] * self.nrow
        nz_v = [None] * len(self.v_row)
        nz_r, beta = [], [None] * self.ncol
        vc, vr = self.v_colind, self.v_row
        for c in range(self.ncol):
            column = self.pc[c]
            for k in range(self.a_colind[column], self.a_colind[column + 1]):
                x[self.prinv[self.a_row[k]]] = nz_a[k]
            for k in range(self.r_colind[c], self.r_colind[c + 1]):
                r = self.r_row[k]
                if r >= c:
                    break
                _reflect(x, nz_v, vr, range(vc[r], vc[r + 1]), beta[r])
                nz_r.append(x[r])
                x[r] = ca.SX(0)
            for k in range(vc[c], vc[c + 1]):
                nz_v[k] = x[vr[k]]
                x[vr[k]] = ca.SX(0)
            house = nz_v[vc[c]:vc[c + 1]]
            s, beta[c] = _house(house, len(house))
            nz_v[vc[c]:vc[c + 1]] = house
            nz_r.append(s)
        return nz_v, nz_r, beta

    def solve(self, factors, b: list) -> list:
        """``casadi_qr_solve`` (one right-hand side, not transposed): ``A^-1 b``."""
        nz_v, nz_r, beta = factors
        w = [ca.SX(0)] * self.nrow
        for c in range(self.ncol):
            w[self.prinv[c]] = b[c]
        vc, vr = self.v_colind, self.v_row
        for c in range(self.ncol):  # casadi_qr_mv, transposed: Q' w
            _reflect(w, nz_v, vr, range(vc[c], vc[c + 1]), beta[c])
        for c in range(self.ncol - 1, -1, -1):  # casadi_qr_trs: R w = Q' b, backwards
            for k in range(self.r_colind[c + 1] - 1, self.r_colind[c] - 1, -1):
                r = self.r_row[k]
                if r == c:
                    w[r] = w[r] / nz_r[k]
                else:
                    w[r] = w[r] - nz_r[k] * w[c]
        x = [None] * self.ncol
        for c in range(self.ncol):
            x[self.pc[c]] = w[c]
        return x


class DenseLU:
    """Gaussian elimination without pivoting, in the order of the unknowns, on SX scalars (the
    pattern's structural zeros are skipped): the linear solve of the unrolled iterations of
    small systems. Against ``casadi_qr`` it has no square roots and no branches (row swaps
    written as ``if_else`` cost more than they saved: Henon-Heiles' chunk 1.22 against 1.08 us
    per step with partial pivoting, 0.60 without, side by side).

    Why no pivoting is safe here: the step's Jacobian is ``I + O(tau)`` in its canonical block,
    so its pivots stay near 1 for the steps a march takes, and the last pivot, the energy row's
    Schur complement, vanishes only where the step itself is singular. Where a pivot does come
    out small (a leading minor such as ``1 + tau^2/4 V_qq`` near zero while the matrix is
    regular), it spoils the Newton update, not the result: the residual is always the step's
    own, so the iterations then do not stop, and ``fast_newton`` (with its QR) goes on from
    where they left off; a zero pivot makes the step non-finite, which the acceptance test
    rejects, and the careful path redoes it. The iterates differ from ``fast_newton``'s in
    the last bits."""

    def __init__(self, pattern: ca.Sparsity):
        self.pattern = pattern
        self.ncol = pattern.size2()
        rows, columns = pattern.get_triplet()
        self.entries = list(zip(rows, columns, strict=True))

    def factor(self, nz_a: list) -> list:
        """The matrix as rows of SX scalars (zeros where the pattern has none)."""
        a = [[ca.SX(0)] * self.ncol for _ in range(self.ncol)]
        for k, (r, c) in enumerate(self.entries):
            a[r][c] = nz_a[k]
        return a

    def solve(self, a: list, b: list) -> list:
        """``A^-1 b`` by elimination below each diagonal entry, then back substitution."""
        n = self.ncol
        a, b = [row[:] for row in a], list(b)
        for c in range(n):
            for r in range(c + 1, n):
                if _structural_zero(a[r][c]):
                    continue
                factor = a[r][c] / a[c][c]
                for j in range(c + 1, n):
                    a[r][j] = a[r][j] - factor * a[c][j]
                b[r] = b[r] - factor * b[c]
        x = [None] * n
        for i in range(n - 1, -1, -1):
            total = b[i]
            for j in range(i + 1, n):
                total = total - a[i][j] * x[j]
            x[i] = total / a[i][i]
        return x


def _structural_zero(value) -> bool:
    return isinstance(value, ca.SX) and value.is_zero()


def newton_iteration(qr: SparseQR | DenseLU, *, abstol: float,
                     abstol_step: float) -> ca.Function:
    """One iteration of ``fast_newton`` as an SX function of symbols (so that no simplification
    reaches across into the Jacobian's expression):
    ``(J, g, x, stopped) -> (x_next, stopped_next)``."""
    n = qr.ncol
    J, g = ca.SX.sym("J", qr.pattern), ca.SX.sym("g", n)
    x, stopped = ca.SX.sym("x", n), ca.SX.sym("stopped")
    small_residual = norm_inf([g[i] for i in range(n)]) <= abstol
    dx = qr.solve(qr.factor([J.nz[k] for k in range(J.nnz())]), [g[i] for i in range(n)])
    update = ca.logic_and(ca.logic_not(stopped), ca.logic_not(small_residual))
    x_next = [ca.if_else(update, x[i] + (-1.0) * dx[i], x[i]) for i in range(n)]
    small_step = small_update(dx, [x[i] for i in range(n)], abstol_step)
    stopped_next = ca.logic_or(stopped, ca.logic_or(small_residual, small_step))
    return ca.Function("newton_iteration", [J, g, x, stopped],
                       [ca.vertcat(*x_next), stopped_next])


def unrolled_newton(name: str, residual: ca.Function, options: dict, *,
                    iterations: int, check_after: bool = False,
                    inline: bool = False, linear: str = "qr",
                    at_root: ca.Function | None = None, border: int = 0) -> ca.Function:
    """``fast_newton`` on ``residual(x, w)`` with ``options`` (``abstol``, ``abstolStep``,
    ``max_iter``) as ``iterations`` unrolled iterations, then, only where those did not stop,
    ``fast_newton`` itself for the iterations left: ``(x0, w) -> x``, the same result.

    With ``check_after`` the iteration after the unrolled ones is written as its first test
    only: the residual at the last iterate against ``abstol``, which is where ``fast_newton``
    stops on most steps (on every step of the paper's example, after three updates from the RK4
    predictor); where that test fails, ``fast_newton`` goes on from the same iterate and
    computes that iteration in full, so the result is the same.

    The Jacobian is ``fast_newton``'s own ``jac_g_x``, called as ``fast_newton`` calls it. With
    ``inline`` the unrolled iterations are one SX function with common subexpressions merged
    (``cse``): what depends on ``w`` only (for an energy step the previous interval's energy and
    the time factors at its clock) is computed once, not once per iteration, and each
    iteration's sines and cosines once. Merging only shares a value between identical
    operations on identical operands, so the bits are those of the separate calls (tested);
    the generated code grows with the unrolled QR, so it pays for small systems only.

    ``linear``: ``"qr"`` solves each update as ``fast_newton`` does (``casadi_qr``), so the
    result is ``fast_newton``'s to the last bit; ``"lu"`` solves it by `DenseLU`
    (cheaper; the result is then a root to the same tolerance, not the same bits).

    ``at_root``: an optional SX function ``(x, w) -> (...)`` of the result (the step's check),
    whose outputs are returned after ``x``. Inlined, it is computed with the unrolled
    iterations, merged with their last residual test, and passed through where they stop;
    where ``fast_newton`` goes on, it is computed again at ``fast_newton``'s result. Either way
    its values are those of ``at_root`` at the returned ``x``."""
    if linear not in ("qr", "lu"):
        raise ValueError(f"linear must be 'qr' or 'lu', got {linear!r}")
    jacobian = ca.rootfinder(name, "fast_newton", residual, dict(options)).get_function("jac_g_x")
    solver = (SparseQR if linear == "qr" else DenseLU)(jacobian.sparsity_out(0))
    iteration = newton_iteration(solver, abstol=options["abstol"],
                                 abstol_step=options["abstolStep"])
    kind = ca.SX if inline else ca.MX
    x0 = kind.sym("x0", jacobian.sparsity_in(0))
    w = kind.sym("w", jacobian.sparsity_in(1))
    x, stopped = x0, kind(0)
    for _ in range(iterations):
        J, g = jacobian(x, w)
        x, stopped = iteration(J, g, x, stopped)
    done = iterations
    # inline, lu, check_after: the rest begins with the update of the iteration whose test
    # failed here, from this test's residual (chain_newton(tested=True)), not with that test
    # again: the same bits, one residual and check fewer where the rest runs
    tested = inline and check_after and linear == "lu"
    carried = []  # the last test's residual, carried through the switch when tested
    if check_after:
        _, g = jacobian(x, w)  # inline: J unused, only g's expressions stay
        g_sym = ca.SX.sym("g", g.sparsity())
        small = ca.Function("small_residual", [g_sym],
                            [norm_inf([g_sym[i] for i in range(g.numel())])
                             <= options["abstol"]])
        stopped = ca.logic_or(stopped, small(g))
        carried = [g] if tested else []
    values = []  # at_root's outputs at the unrolled iterate, carried through the switch
    if inline:
        values = at_root.call([x, w]) if at_root is not None else []
        unrolled = ca.Function(name + "_unrolled", [x0, w], [x, stopped, *carried, *values],
                               {"cse": True})
        x0 = ca.MX.sym("x0", jacobian.sparsity_in(0))
        w = ca.MX.sym("w", jacobian.sparsity_in(1))
        x, stopped, *values = unrolled.call([x0, w])
        carried, values = values[:len(carried)], values[len(carried):]
    left = {**options, "max_iter": options["max_iter"] - done}
    x_sym, w_sym = ca.MX.sym("x", x0.sparsity()), ca.MX.sym("w", w.sparsity())
    g_syms = [ca.MX.sym("g", g.sparsity()) for g in carried]
    v_syms = [ca.MX.sym(f"v{i}", value.sparsity()) for i, value in enumerate(values)]
    finish_done = ca.Function("done", [x_sym, w_sym, *g_syms, *v_syms], [x_sym, *v_syms])
    if linear == "qr":  # fast_newton's bits: its own loop goes on
        x_rest = ca.rootfinder(name + "_rest", "fast_newton", residual, left)(x_sym, w_sym)
        again = at_root.call([x_rest, w_sym]) if values else []
    else:  # its tests with the round-off-relative step test (ROUNDOFF_STEPS), as unrolled
        x_rest, *again = chain_newton(name + "_rest", residual, left, border=border,
                                      at_root=at_root if values else None, tested=tested
                                      ).call([x_sym, w_sym, *g_syms])
    # A switch on functions of (x, w) only: ca.if_else would put the unrolled iterations into
    # both branches. The rest runs only where the unrolled iterations did not stop.
    finish = ca.Function.if_else(name + "_finish", finish_done,
                                 ca.Function("go_on", [x_sym, w_sym, *g_syms, *v_syms],
                                             [x_rest, *again]))
    solved, *values = finish.call([stopped, x, w, *carried, *values])
    if at_root is not None and not inline:
        values = at_root.call([solved, w])
    return ca.Function(name, [x0, w], [solved, *values], {"never_inline": True})
