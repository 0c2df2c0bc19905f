"""The tangent map of the energy-rule march, propagated inside the march's compiled chunk.

Notation of docs/theory.md: nodes ``t_k``, steps ``tau_k = t_{k+1} - t_k``, ``z_k = (q_k, p_k)``
in ``R^2n``, ``f = J grad H``. Step ``k >= 1`` of an energy rule solves ``F(x; w) = 0`` for
``x = (z_{k+1}, tau_k)`` (``StepFunctions.energy_residual``: the ``2n`` canonical equations of
interval ``k`` and the energy equation at node ``k``), with
``w = (t_{k-1}, t_k, z_{k-1}, z_k, theta, drift)``. The step is therefore a map of the chunk's
state ``s_k = (t_{k-1}, t_k, z_{k-1}, z_k)`` to ``s_{k+1} = (t_k, t_k + tau_k, z_k, z_{k+1})``,
and its derivative follows by implicit differentiation at the accepted root, ``tau_k`` being an
unknown like ``z_{k+1}``::

    A dx = -B X_k,      A = dF/dx  ((2n+1)^2, the Newton Jacobian),
                        B = dF/d(t_{k-1}, t_k, z_{k-1}, z_k)  ((2n+1) x (4n+2)),
    X_k = (dt_{k-1}, dt_k, dz_{k-1}, dz_k),   X_{k+1} = (dt_k, dt_k + dtau_k, dz_k, dz_{k+1}).

The row scaling of the energy equation by ``tau_{k-1}`` changes ``B`` by a multiple of the
residual, zero at the root, so the tangent does not depend on it. ``A`` is nonsingular where
the step is solvable (the Schur complement of its energy row is ``O(tau)/tau_{k-1} = O(1)``),
and it is solved by elimination without pivoting (its leading block is ``I + O(tau)``).
Step 0 (length ``tau_0``, given) is the fixed-length step ``G(z_1; t_0, t_1, z_0) = 0``:
``dz_1 = -G_{z_1}^{-1} G_{z_0} dz_0`` at ``dt_0 = dt_1 = 0``.

The steps never depend on the tangent: the tangent reads the root ``x`` and nothing computed
from it reaches ``x``; the chunk's step is `FastChunk`'s own step function, called unchanged,
so the nodes are the plain march's bit for bit (compiled with ``-ffp-contract=off``; tested).

What the norm (and the QR) sees of ``X_k``, the *observation*:

- ``sync``: ``w_k = dz_k - f(z_k, t_k) dt_k``, the perturbed discrete solution compared with
  the reference at equal time. A start perturbation ``dz_0`` changes every later step
  (``dtau_k = O(|dz_0|)``), so the perturbed nodes drift in time (``dt_k`` grows like ``t``);
  the synchronous vector converges to the exact variational vector ``Phi_t'(z_0) dz_0`` at
  ``t = t_k``, to second order in ``tau_0`` (docs/chaos/README.md). Used for MEGNO, the fast
  Lyapunov indicator and the largest exponent.
- ``level``: the fixed-level node map ``Phi_E: z_k -> z_{k+1}`` at the discrete energy
  ``E = H(zeta_{k-1})`` (autonomous ``H``: the step sees ``z_{k-1}`` only through that level
  and ``t`` only through ``tau_{k-1}``). Its tangent is the recurrence above with
  ``X = (0, 0, -dz, dz)`` re-imposed each step (``dE = 0``, ``dt = 0``), observed as ``dz``.
  ``Phi_E`` is symplectic, so with a symplectic-flag frame the QR exponents pair exactly
  (``spectrum.py``). Used for the full spectrum.

Renormalisation after every step: one vector is divided by ``|w_{k+1}|`` and
``ell_k = ln |w_{k+1}|`` is an output of the step; ``m > 1`` vectors are orthonormalised by
modified Gram-Schmidt on their observations (the same column operations on ``X``), ``ell``
holding ``ln R_jj``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...errors import InputError
from ...physics import vector_field_function
from ..marching.chunk import ChunkLayout, FastChunk, step_options

OBSERVATIONS = ("sync", "level")


def eliminate(A: ca.SX, B: ca.SX) -> ca.SX:
    """``A^{-1} B`` by Gaussian elimination without pivoting, written out in SX (``A`` small
    and square, its pivots of order one: module docstring); the elimination's expressions are
    the same for every column of ``B`` and merge under common-subexpression elimination."""
    size = A.size1()
    a = [[A[i, j] for j in range(size)] for i in range(size)]
    b = [[B[i, j] for j in range(B.size2())] for i in range(size)]
    for k in range(size):
        for i in range(k + 1, size):
            factor = a[i][k] / a[k][k]
            a[i] = [a[i][j] - factor * a[k][j] if j > k else a[i][j] for j in range(size)]
            b[i] = [b[i][j] - factor * b[k][j] for j in range(len(b[i]))]
    x = [None] * size
    for i in reversed(range(size)):
        row = b[i]
        for j in range(i + 1, size):
            row = [row[c] - a[i][j] * x[j][c] for c in range(len(row))]
        x[i] = [value / a[i][i] for value in row]
    return ca.vertcat(*[ca.horzcat(*row) for row in x])


def gram_schmidt(W: ca.SX, X: ca.SX) -> tuple[ca.SX, ca.SX]:
    """Modified Gram-Schmidt on the columns of the observations ``W`` in their order (no
    pivoting: the frame's order is its flag), the same column operations on the tangent
    states ``X`` (``W`` is linear in ``X``). Returns ``(X / R, ln diag R)``."""
    w = [W[:, j] for j in range(W.size2())]
    x = [X[:, j] for j in range(X.size2())]
    logs = []
    for j in range(len(w)):
        for i in range(j):
            r = ca.dot(w[i], w[j])
            w[j], x[j] = w[j] - r * w[i], x[j] - r * x[i]
        norm = ca.norm_2(w[j])
        w[j], x[j] = w[j] / norm, x[j] / norm
        logs.append(ca.log(norm))
    return ca.horzcat(*x), ca.vertcat(*logs)


class TangentMap:
    """The derivative of one march step as CasADi functions (module docstring), built from the
    march's own step functions (``StepFunctions``) for an energy rule.

    ``width = 4n + 2``: the size of one tangent state ``X = (dt_{k-1}, dt_k, dz_{k-1}, dz_k)``.
    """

    def __init__(self, system, functions):
        n = system.n
        self.n, self.width = n, 4 * n + 2
        self.ntheta = system.theta.numel()
        self.field = vector_field_function(system)
        residual = functions.energy_residual
        x, w = ca.SX.sym("x", 2 * n + 1), ca.SX.sym("w", residual.size1_in(1))
        g = residual(x, w)
        self.jacobians = ca.Function("step_jacobians", [x, w], [
            ca.densify(ca.jacobian(g, x)), ca.densify(ca.jacobian(g, w[:self.width]))])
        fixed = functions.fixed_residual
        z_b, w_a = ca.SX.sym("z_b", 2 * n), ca.SX.sym("w_a", fixed.size1_in(1))
        g0 = fixed(z_b, w_a)
        # step 0: G(z_1; t_0, t_1, z_0), the derivative in z_1 and in z_0
        self.first_jacobians = ca.Function("first_step_jacobians", [z_b, w_a], [
            ca.densify(ca.jacobian(g0, z_b)), ca.densify(ca.jacobian(g0, w_a[2:2 + 2 * n]))])

    def step(self, vectors: int, observation: str) -> ca.Function:
        """``(X, t_prev, t_mid, t_next, z_prev, z_mid, z_next, theta, drift, weights) -> (X',
        ell)``: ``vectors`` tangent states (``X`` stacked column by column) carried over one
        accepted step, renormalised on their ``observation`` weighted by ``weights``
        (``physics.hamiltonian.symplectic_weights``: ``|W w|``, the norm in no coordinate's units);
        ``ell`` the logs of the growth."""
        if observation not in OBSERVATIONS:
            raise InputError(f"observation must be one of {OBSERVATIONS}, got {observation!r}")
        n, m = self.n, vectors
        X = ca.SX.sym("X", self.width * m)
        t_prev, t_mid, t_next, drift = (ca.SX.sym(s) for s in ("t_prev", "t_mid", "t_next",
                                                                 "drift"))
        z_prev, z_mid, z_next = (ca.SX.sym(s, 2 * n) for s in ("z_prev", "z_mid", "z_next"))
        theta = ca.SX.sym("theta", self.ntheta)
        weights = ca.SX.sym("weights", 2 * n)
        states = ca.reshape(X, self.width, m)
        A, B = self.jacobians(ca.vertcat(z_next, t_next - t_mid),
                              ca.vertcat(t_prev, t_mid, z_prev, z_mid, theta, drift))
        dx = -eliminate(A, ca.mtimes(B, states))
        dz_next, dt_mid = dx[:2 * n, :], states[1, :]
        if observation == "level":  # the fixed-level map: dE = 0, dt = 0 re-imposed
            after = ca.vertcat(ca.SX.zeros(2, m), -dz_next, dz_next)
            seen = dz_next
        else:
            dt_next = dt_mid + dx[2 * n, :]
            after = ca.vertcat(dt_mid, dt_next, states[2 + 2 * n:, :], dz_next)
            seen = dz_next - ca.mtimes(self.field(z_next, t_next, theta), dt_next)
        seen = seen * ca.repmat(weights, 1, m)
        if m == 1:
            norm = ca.norm_2(seen)
            after, logs = after / norm, ca.log(norm)
        else:
            after, logs = gram_schmidt(seen, after)
        return ca.Function("tangent_step", [X, t_prev, t_mid, t_next, z_prev, z_mid, z_next,
                                            theta, drift, weights], [ca.vec(after), logs],
                           {"cse": True})

    def first_step(self, t0: float, t1: float, z0, z1, theta, dz0: np.ndarray) -> np.ndarray:
        """``X_1`` (``width x m``) from ``dz_0`` (``2n x m``) over step 0 at fixed ``tau_0``
        (``dt_0 = dt_1 = 0``)."""
        G1, G0 = (np.asarray(J) for J in self.first_jacobians(
            z1, np.concatenate([[t0, t1], z0, np.asarray(theta, float).ravel()])))
        dz1 = -np.linalg.solve(G1, G0 @ dz0)
        zeros = np.zeros((2, dz0.shape[1]))
        return np.vstack([zeros, dz0, dz1])


class TangentChunk(FastChunk):
    """`FastChunk`'s energy steps carrying ``vectors`` tangent states, renormalised on their
    ``observation`` (module docstring), in the same compiled call.

    The state is ``(plain, tangent)``: ``plain`` is `FastChunk`'s own state
    (``plain_state``), ``tangent`` the ``width * vectors`` numbers of ``X``; the output of each
    step is ``(plain, ell)``: `FastChunk`'s per-step output (``plain_output``) and the logs of
    the step's growth. The step function is `FastChunk`'s, called as it is and followed by
    `TangentMap.step` on its root: nothing flows back into the nodes.
    """

    def __init__(self, system, scheme, functions, *, vectors: int, observation: str,
                 chunk: int, compiler, cache_dir):
        if not scheme.variable_steps:
            raise InputError(f"tangent vectors need an energy rule (vddvp or lee), got scheme "
                             f"{scheme.rule!r}")
        self.tangent = TangentMap(system, functions)
        self.vectors, self.observation = int(vectors), observation
        super().__init__(system, scheme, functions, chunk=chunk, compiler=compiler,
                         cache_dir=cache_dir)

    def _energy_step(self, functions, theta):
        plain = self.energy_step(functions, theta)
        self.plain_state, self.plain_output = self.state, self.output
        m = self.vectors
        self.state = ChunkLayout(("plain", self.plain_state.size),
                                 ("tangent", self.tangent.width * m),
                                 ("weights", 2 * self.tangent.n))
        self.output = ChunkLayout(("plain", self.plain_output.size), ("ell", m))
        state = ca.SX.sym("state", self.state.size)
        parameters = ca.SX.sym("parameters", plain.size1_in(1))
        s = self.state.split(state)
        after, outputs = plain(s["plain"], parameters)
        before, out = self.plain_state.split(s["plain"]), self.plain_output.split(outputs)
        tangent, ell = self.tangent.step(m, self.observation)(
            s["tangent"], before["t_prev"], before["t_mid"], out["t_next"], before["z_prev"],
            before["z_mid"], out["z_next"], parameters[:self.tangent.ntheta], before["drift"],
            s["weights"])
        return ca.Function("step", [state, parameters],
                           [ca.vertcat(after, tangent, s["weights"]),
                            ca.vertcat(outputs, ell)],
                           step_options(functions.energy_residual.numel_in(0)))

    def tangent_state(self, t_prev, t_mid, z_prev, z_mid, drift, X: np.ndarray,
                      weights: np.ndarray) -> np.ndarray:
        """The chunk's state from nodes ``k - 1`` and ``k``, the drift, the tangent states
        ``X`` (``width x vectors``) and the norm's ``weights`` (carried unchanged)."""
        plain = self.plain_state.pack(t_prev=t_prev, t_mid=t_mid, z_prev=z_prev, z_mid=z_mid,
                                      drift=drift)
        return self.state.pack(plain=plain, tangent=np.asarray(X, float).ravel(order="F"),
                               weights=np.asarray(weights, float))

    def run(self, state: np.ndarray, parameters: np.ndarray) -> tuple[dict, np.ndarray]:
        """One call: ``chunk`` steps from ``state``. Returns the per-step columns by name
        (`FastChunk`'s outputs, ``good`` as booleans, ``drift`` after each step, ``ell``
        ``(chunk, vectors)`` and ``tangent``, the tangent states after each step, each row
        ``X`` stacked column by column) and the state after each step
        ``(chunk, state size)``; copies, not the call's buffers."""
        tiled = np.broadcast_to(parameters, (self.chunk, parameters.size))
        states, outputs = (np.array(a) for a in self._buffer(state, tiled))
        size = self.plain_output.size
        columns = self.plain_output.columns(outputs[:, :size])
        columns["good"] = columns["good"] != 0
        columns["ell"] = outputs[:, size:].reshape(self.chunk, self.vectors)
        plain = self.plain_state.size
        columns["drift"] = self.plain_state.columns(states[:, :plain])["drift"]
        columns["tangent"] = states[:, plain:plain + self.tangent.width * self.vectors]
        return columns, states
