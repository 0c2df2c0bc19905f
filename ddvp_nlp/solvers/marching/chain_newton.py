"""The compiled march's Newton for steps with many unknowns: cost and generated code linear in
``n`` where the step's Jacobian is banded (chains, lattices, discretised fields).

Why a second Newton. The energy step's unknowns are ``x = (z_{k+1}, tau_k)``; its Jacobian is
the canonical block ``A`` (``2n x 2n``, block tridiagonal for a chain with nearest-neighbour
springs) bordered by the ``tau`` column ``b`` and the energy row ``c``::

    J = [ A   b ]
        [ c'  d ]

Any QR of ``J`` (``fast_newton``'s ``casadi_qr``, `step_newton.unrolled_newton`'s) fills its
``R`` completely: ``R`` has the pattern of the Cholesky factor of ``J'J``, and the dense energy
row makes ``J'J`` dense. Unrolled, that is ``O(n^3)`` straight-line code per iteration: on the
alpha-FPU chain the generated C grew from 258 kB (n = 8) to 4.3 MB (n = 32), gcc took 54 s at
n = 32 and did not finish in 20 minutes at n = 64, and a step cost 12 us at n = 8, 351 us at
n = 32 (measured beside this module's prototype).

Gaussian elimination without pivoting, with the border (``tau``) last, fills only what the
elimination of ``A`` fills: ``O(n)`` for a band. `SparseLU` does it on SX scalars in a
fill-reducing order (`fill_reducing_order`), skipping structural zeros, so the operations and
the Python work building them are those of the fill pattern only. Why no pivoting is safe: as
for `step_newton.DenseLU`, the canonical block is ``I + O(tau)`` and a symmetric permutation
keeps its diagonal on the diagonal; the last pivot is the energy row's Schur complement, which
vanishes only where the step itself is singular. A small pivot spoils an update, not the
result: the residual is the step's own, so Newton does not stop on a wrong root, and a
non-finite step is refused by the acceptance test and redone on the careful path.

`chain_newton` is ``fast_newton``'s loop (the same ``jac_g_x``, tests and order) as a chain of
conditional calls of two SX functions generated once, the residual test (with the step's check
merged in) and the update: a step pays for the iterations it takes, nothing is unrolled. On the
alpha-FPU chain (prototype, side by side): a step 3.2 us at n = 8, 13 us at n = 32, 27 us at
n = 64 (8.4 times n = 8); the chunk's C 228 kB at n = 8, 877 kB at n = 64, gcc 1.6 and 12.5 s.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["SparseLU", "chain_newton", "fill_reducing_order", "norm_inf", "small_update"]

# An update is small when it is at most ``abstolStep`` or at most this many units of round-off
# of the iterate: ``|dx|_inf <= max(abstolStep, ROUNDOFF_STEPS * eps * |x|_inf)``, norm-wise
# because the round-off of the large components reaches the others through ``J^-1`` (a
# component-wise test left the step length's updates above its own round-off). ``fast_newton``
# tests ``|dx|_inf <= abstolStep`` alone, which an iterate larger than ``abstolStep / eps``
# (about 45 here: a winding azimuth, a coordinate offset by a constant) cannot pass: its updates
# stay at its round-off, and every such step ran all ``max_iter`` iterations (a spherical
# pendulum in angles: 7-13 us a step against 1.8 before its azimuth passed 1000 rad, issue 49).
# For iterates below ``abstolStep / (ROUNDOFF_STEPS * eps)`` (11.3) the test is
# ``fast_newton``'s, to the bit.
ROUNDOFF_STEPS = 4.0


def small_update(dx, x, abstol_step: float) -> ca.SX:
    """Whether the update ``dx`` of the iterate ``x`` (lists of SX) is small:
    ``|dx|_inf <= max(abstol_step, ROUNDOFF_STEPS * eps * |x|_inf)``."""
    unit = ROUNDOFF_STEPS * float(np.finfo(float).eps)
    return norm_inf(dx) <= ca.fmax(abstol_step, unit * norm_inf(x))


def norm_inf(values) -> ca.SX:
    """``casadi_norm_inf``: ``fmax`` from 0 over ``|v_i|`` (``fmax`` ignores a NaN)."""
    result = ca.SX(0)
    for value in values:
        result = ca.fmax(result, ca.fabs(value))
    return result

# "auto" ordering: AMD when its elimination needs less than this share of the natural order's
AMD_GAIN = 0.75


def _order(pattern: ca.Sparsity, border: int, ordering: str) -> list:
    n = pattern.size2()
    m = n - border
    if ordering == "natural" or m <= 1:
        head = list(range(m))
    elif ordering == "amd":
        block, _ = pattern.sub(list(range(m)), list(range(m)), False)
        head = list((block + block.T).amd())
    else:
        raise ValueError(f"unknown ordering {ordering!r}")
    return head + list(range(m, n))


def elimination_cost(pattern: ca.Sparsity, perm: list) -> int:
    """Multiply-adds of the elimination (factor and one solve) of ``pattern`` in the order
    ``perm``, counted on the structure, fill included."""
    position = {v: k for k, v in enumerate(perm)}
    rows = [set() for _ in perm]
    for r, c in zip(*pattern.get_triplet(), strict=True):
        rows[position[r]].add(position[c])
    below = [set() for _ in perm]
    for r, row in enumerate(rows):
        for c in row:
            if c < r:
                below[c].add(r)
    cost = 0
    for c, pivot_row in enumerate(rows):
        right = [j for j in pivot_row if j > c]
        for r in below[c]:
            cost += 1 + len(right)
            for j in right:
                if j not in rows[r]:
                    rows[r].add(j)
                    if j < r:
                        below[j].add(r)
    return cost + sum(len(row) for row in rows)


def fill_reducing_order(pattern: ca.Sparsity, border: int, ordering: str = "auto") -> list:
    """A permutation of the unknowns: the leading ``ncol - border`` in ``ordering``, the
    ``border`` unknowns last. ``"natural"``: as they are; ``"amd"``: approximate minimum
    degree of the leading block's symmetrised pattern; ``"auto"``: natural unless AMD's
    elimination needs less than ``AMD_GAIN`` of its operations (for ``H = T(p) + V(q)`` of a
    chain both are ``O(n)`` and the natural order is kept; where it fills, a ``q`` block
    coupled through ``p``, AMD is taken)."""
    if ordering != "auto":
        return _order(pattern, border, ordering)
    natural, amd = _order(pattern, border, "natural"), _order(pattern, border, "amd")
    if elimination_cost(pattern, amd) < AMD_GAIN * elimination_cost(pattern, natural):
        return amd
    return natural


def _is_zero(value) -> bool:
    return isinstance(value, ca.SX) and value.is_zero()


class SparseLU:
    """Elimination without pivoting on SX scalars, in a fill-reducing order, border last (the
    interface of `step_newton.DenseLU`: ``pattern``, ``ncol``, ``factor(nz)``,
    ``solve(factors, b)``).

    ``factor`` takes the matrix's nonzeros in ``pattern``'s order and returns, per permuted
    row, the row of ``U`` (columns at and right of the diagonal) and the multipliers (left of
    it); structural zeros, and SX constant zeros folded in from the Jacobian's expressions,
    are skipped. The operations follow `DenseLU`'s order (for each column the rows below it in
    increasing order, each updated left to right; back substitution right to left), so with
    ``ordering="natural"`` they are `DenseLU`'s to the bit (tested)."""

    def __init__(self, pattern: ca.Sparsity, border: int = 0, ordering: str = "auto"):
        self.pattern = pattern
        self.ncol = n = pattern.size2()
        self.perm = fill_reducing_order(pattern, border, ordering)
        position = [0] * n
        for k, v in enumerate(self.perm):
            position[v] = k
        rows, cols = pattern.get_triplet()
        self.entries = [(position[r], position[c]) for r, c in zip(rows, cols, strict=True)]

    def factor(self, nz_a: list) -> list:
        rows = [{} for _ in range(self.ncol)]
        for k, (r, c) in enumerate(self.entries):
            if not _is_zero(nz_a[k]):
                rows[r][c] = nz_a[k]
        below = [set() for _ in rows]  # rows r > c with an entry in column c
        for r, row in enumerate(rows):
            for c in row:
                if c < r:
                    below[c].add(r)
        for c, pivot_row in enumerate(rows):
            pivot = pivot_row[c]
            right = sorted(j for j in pivot_row if j > c)
            for r in sorted(below[c]):
                row = rows[r]
                factor = row[c] / pivot
                row[c] = factor
                for j in right:
                    if j in row:
                        row[j] = row[j] - factor * pivot_row[j]
                    else:  # fill-in (DenseLU computes 0 - f a, which SX makes -(f a))
                        row[j] = -(factor * pivot_row[j])
                        if j < r:
                            below[j].add(r)
        return rows

    def solve(self, lu: list, b: list) -> list:
        """``A^-1 b``: forward substitution with the multipliers, back substitution with
        ``U``, in the permuted order."""
        y = [b[v] for v in self.perm]
        for i, row in enumerate(lu):
            total = y[i]
            for j in sorted(j for j in row if j < i):
                total = total - row[j] * y[j]
            y[i] = total
        xp = [None] * self.ncol
        for i in range(self.ncol - 1, -1, -1):
            total = y[i]
            for j in sorted(j for j in lu[i] if j > i):
                total = total - lu[i][j] * xp[j]
            xp[i] = total / lu[i][i]
        x = [None] * self.ncol
        for k, v in enumerate(self.perm):
            x[v] = xp[k]
        return x


def chain_newton(name: str, residual: ca.Function, options: dict, *, border: int,
                 at_root: ca.Function | None = None, ordering: str = "auto",
                 tested: bool = False) -> ca.Function:
    """``fast_newton`` on ``residual(x, w)`` with ``options`` (``abstol``, ``abstolStep``,
    ``max_iter``): ``(x0, w) -> (x, *at_root(x, w))``, each update solved by `SparseLU`
    (``border``: the unknowns eliminated last, 1 for the energy step's ``tau``, 0 for a fixed
    step).

    Iteration ``k`` (``k = 1 .. max_iter``): ``test(x, w) -> (g, |g|_inf <= abstol,
    *at_root(x, w))``; stop with ``x`` if the test passes; else ``update(x, w, g) -> (x -
    J^-1 g, |J^-1 g|_inf <= abstolStep)``; stop with the new ``x`` if the update was small;
    else iteration ``k + 1``; after ``max_iter`` the last iterate. These are ``fast_newton``'s
    tests in its order with its ``jac_g_x``; only the linear solve differs. The chain is made
    of ``Function.if_else`` switches (a branch in the generated C, one branch evaluated), so a
    step runs the iterations it needs: 1-3 updates on the alpha-FPU chain, where the unrolled
    form computes four Jacobians and factorisations on every step. ``at_root``'s outputs come
    from the test that stopped the chain (sharing the residual's terms); where the chain stops
    on a small update or at ``max_iter``, the test runs once more at the result for them.

    ``tested``: the caller has already made iteration 1's test and it failed (`unrolled_newton`
    after its ``check_after`` test): the function is ``(x0, w, g) -> ...`` with ``g`` that
    test's residual at ``x0``, and iteration 1 begins with its update (the same bits: the test
    would compute the same ``g`` and fail again)."""
    abstol, abstol_step = options["abstol"], options["abstolStep"]
    jacobian = ca.rootfinder(name, "fast_newton", residual, dict(options)).get_function("jac_g_x")
    solver = SparseLU(jacobian.sparsity_out(0), border, ordering)
    n = solver.ncol
    x = ca.SX.sym("x", jacobian.sparsity_in(0))
    w = ca.SX.sym("w", jacobian.sparsity_in(1))
    g = residual.call([x, w])[0]
    J, _ = jacobian.call([x, w])
    values = at_root.call([x, w]) if at_root is not None else []
    test = ca.Function(name + "_test", [x, w],
                       [g, norm_inf([g[i] for i in range(n)]) <= abstol, *values],
                       {"cse": True})
    g_in = ca.SX.sym("g", n)
    dx = solver.solve(solver.factor([J.nz[k] for k in range(J.nnz())]),
                      [g_in[i] for i in range(n)])
    update = ca.Function(name + "_update", [x, w, g_in],
                         [ca.vertcat(*[x[i] + (-1.0) * dx[i] for i in range(n)]),
                          small_update(dx, [x[i] for i in range(n)], abstol_step)],
                         {"cse": True})
    # the chain on MX: level k = (x, w) -> (x, *values) from iteration k on
    xm, wm = ca.MX.sym("x", x.sparsity()), ca.MX.sym("w", w.sparsity())
    gm = ca.MX.sym("g", n)
    vm = [ca.MX.sym(f"v{i}", value.sparsity()) for i, value in enumerate(values)]
    _, _, *at_x = test(xm, wm)
    final = ca.Function(name + "_final", [xm, wm], [xm, *at_x])
    done = ca.Function(name + "_done", [xm, wm, gm, *vm], [xm, *vm])
    level = final
    for k in range(options["max_iter"], 0, -1):
        x_next, small_step = update(xm, wm, gm)
        after = ca.Function.if_else(f"{name}_after{k}", final, level)
        go_on = ca.Function(f"{name}_update{k}", [xm, wm, gm],
                            after.call([small_step, x_next, wm]))
        if k == 1 and tested:  # iteration 1 from its update (its test failed in the caller)
            solved, *out = go_on.call([xm, wm, gm])
            return ca.Function(name, [xm, wm, gm], [solved, *out], {"never_inline": True})
        branch = ca.Function.if_else(
            f"{name}_branch{k}", done,
            ca.Function(f"{name}_go_on{k}", [xm, wm, gm, *vm], go_on.call([xm, wm, gm])))
        g_k, small, *v_k = test(xm, wm)
        level = ca.Function(f"{name}_iteration{k}", [xm, wm],
                            branch.call([small, xm, wm, g_k, *v_k]))
    x0 = ca.MX.sym("x0", x.sparsity())
    solved, *out = level.call([x0, wm])
    return ca.Function(name, [x0, wm], [solved, *out], {"never_inline": True})
