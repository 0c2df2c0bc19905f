"""The constrained step of ``constrained.py`` with its multipliers eliminated: the discrete
null-space method (Betsch 2005; Leyendecker, Marsden and Ortiz 2008) on the RATTLE-form
equations of a Hamiltonian system.

The multiplier form solves, per step ``a -> b``, the ``2n`` interval rows on the interval
momenta ``p_a^+ = p_a - (tau/2) G_a^T lambda`` and ``p_b^- = p_b + (tau/2) G_b^T mu`` and the
``2m`` node rows at ``b``, for ``(z_b, lambda, mu)``. The same equations, reduced:

- The interval's unknowns are ``(q_b, P)`` with ``P = alpha p_b^- + beta p_a^+`` (the momentum
  argument of the interval, ``action.py``). The momentum row
  ``p_b^- - p_a^+ = -tau H_q(Q, P, s) =: d`` then gives both interval momenta explicitly,
  ``p_a^+ = P - alpha d`` and ``p_b^- = P + beta d``.
- ``lambda`` is eliminated by a null-space matrix ``N_a`` of ``G_a = G(q_a, t_a)``
  (``G_a N_a = 0``, ``n x (n - m)``, orthonormal, from a Householder QR of ``G_a^T`` made once
  per step: ``q_a`` is known): ``p_a^+ - p_a`` lies in the range of ``G_a^T`` exactly when
  ``N_a^T (p_a^+ - p_a) = 0`` (``n - m`` rows).
- ``mu`` and ``p_b`` follow after the solve: ``p_b`` is ``p_b^-`` moved along ``G_b^T`` onto
  the hidden constraint (an ``m x m`` solve per Newton update of ``mu``; one is exact where
  ``H`` is quadratic in ``p``).

The rows are ``q_b - q_a - tau H_p(Q, P, s)`` (``n``), ``N_a^T (p_a^+ - p_a)`` (``n - m``),
``g(q_b, t_b)`` (``m``) and, for ``vddvp``, the energy row of ``constrained.py`` (the interval
energies read only the interval momenta; where the constraints move, its work term reads
``lambda`` through ``p_a^+ - p_a``: ``solvers/marching/null_space_steps.py``): ``2n`` unknowns
(``2n + 1``) where the multiplier
form has ``2n + 2m`` (``2n + 2m + 1``). Every solution of one is a solution of the other, so
the two forms march the same nodes to the solver's tolerance; ``lambda`` is recovered from
``G_a (p_a^+ - p_a)`` and the multiplier form's own residual judges every step.

What it costs: ``N_a`` is dense, so the ``n - m`` momentum rows of the Newton's Jacobian are
dense where the multiplier form's are as sparse as ``G``. It pays where ``n`` is small (fewer
unknowns), not for long chains (docs/constraints.md, "The null-space form").
"""

from __future__ import annotations

import casadi as ca

from ..cache import cached
from ..physics.constraints import constraint_function
from ..physics.hamiltonian import derivatives_function
from .constrained import interval_momenta

__all__ = ["null_space_basis", "null_space_momenta", "null_space_rows", "projection_parts"]


def _kind(matrix):
    return type(matrix) if isinstance(matrix, (ca.SX, ca.MX)) else ca.DM


def null_space_basis(G):
    """``N`` (``n x (n - m)``) with orthonormal columns and ``G N = 0`` for ``G`` (``m x n``,
    rank ``m``): the last ``n - m`` columns of ``Q`` in the Householder QR ``G^T = Q R``
    (reflections with the sign that avoids cancellation). Takes SX, MX or numbers: on MX its
    graph is ``O(m)`` dense operations (``O(n m (n - m))`` work at run time)."""
    m, n = G.shape
    kind = _kind(G)
    A = kind(G).T
    reflections = []
    for k in range(m):
        x = A[k:, k]
        sign = ca.if_else(x[0] >= 0, 1, -1)
        head = x[0] + sign * ca.norm_2(x)
        v = ca.vertcat(kind.zeros(k, 1), head, x[1:]) if k + 1 < n else \
            ca.vertcat(kind.zeros(k, 1), head)
        v = v / ca.norm_2(v)
        A = A - 2 * ca.mtimes(v, ca.mtimes(v.T, A))
        reflections.append(v)
    basis = ca.vertcat(kind.zeros(m, n - m), kind.eye(n - m))
    for v in reversed(reflections):
        basis = basis - 2 * ca.mtimes(v, ca.mtimes(v.T, basis))
    return basis


def null_space_momenta(system, scheme, t_a, t_b, q_a, q_b, P, theta):
    """``(p_a^+, p_b^-)`` of the interval from its argument ``P`` and its positions (module
    docstring): the momentum row solved for them."""
    Q = scheme.alpha * q_a + scheme.beta * q_b
    tau = t_b - t_a
    s = t_a + tau / 2 if scheme.clock == "midpoint" else t_a
    _, H_q, _, _ = derivatives_function(system)(Q, P, s, theta)
    d = -tau * H_q
    return P - scheme.alpha * d, P + scheme.beta * d


def null_space_rows(system, scheme, t_a, t_b, q_a, p_a, q_b, P, basis, theta):
    """The ``2n`` reduced rows of the interval ``a -> b`` (module docstring), ``basis`` the
    null-space matrix of ``G(q_a, t_a)``; and ``(p_a^+, p_b^-)``."""
    Q = scheme.alpha * q_a + scheme.beta * q_b
    tau = t_b - t_a
    s = t_a + tau / 2 if scheme.clock == "midpoint" else t_a
    _, _, H_p, _ = derivatives_function(system)(Q, P, s, theta)
    plus, minus = null_space_momenta(system, scheme, t_a, t_b, q_a, q_b, P, theta)
    g, _, _ = constraint_function(system)(q_b, t_b, theta)
    rows = ca.vertcat(q_b - q_a - tau * H_p, ca.mtimes(basis.T, plus - p_a), g)
    return rows, plus, minus


def projection_parts(system) -> ca.Function:
    """``(q, p, t, theta) -> (hidden, G, G H_pp G^T)``: what a Newton update of ``mu`` in
    ``p = p^- - (tau/2) G^T mu`` needs (``hidden = G H_p + g_t``; its derivative in ``mu`` is
    ``-(tau/2) G H_pp G^T``)."""
    def build():
        q, p, t, theta = system.q, system.p, system.t, system.theta
        _, G, g_t = constraint_function(system)(q, t, theta)
        _, _, H_p, _ = derivatives_function(system)(q, p, t, theta)
        H_pp = ca.jacobian(H_p, p)
        return ca.Function("hidden_projection", [q, p, t, theta],
                           [ca.mtimes(G, H_p) + g_t, G, ca.mtimes([G, H_pp, G.T])],
                           ["q", "p", "t", "theta"], ["hidden", "G", "A"], {"cse": True})
    return cached(system, "null_space_projection", build)


def previous_momenta(system, t_prev, t_a, z_prev, z_a, lam0, mu0, theta):
    """The previous interval's momenta (for the energy row) from its multipliers."""
    n = system.n
    return interval_momenta(system, t_prev, t_a, z_prev[:n], z_prev[n:], z_a[:n], z_a[n:],
                            lam0, mu0, theta)


__all__ += ["previous_momenta"]
