"""Starting points of the fixed-endpoint solve (docs/theory.md section 6: the Jacobian's condition
number grows like ``N^2``, so the start must be close).

Default (``guess="straight"``), for grids of any length:

1. the ``fixed`` problem on uniform times, from uniform motion between the endpoints;
2. the ``fixed`` problem on times with the predicted site density
   ``tau ~ (f' H_zz f)^(-1/3)``, ``f`` the Hamiltonian vector field (the paper's section 4 for
   ``H = p^2/2 + V``: ``f' H_zz f = V'' p^2 + V'^2``; the expansion ``H(z_mid) = H(z) -
   tau^2 f' H_zz f / 8`` gives the same weight for any ``H``);
3. (``bvp.py``) the scheme's equations with the times released.

Released directly from uniform times, Newton diverged at N = 1e5 on the pendulum; from the
predicted times it took 3-4 iterations at N = 1e3, 1e4 and 1e5 (measured).

``guess="march"`` replaces phase 1 by shooting: march ``fixed`` steps on the uniform grid from
``(q_start, p_0)`` and solve ``q_{N-1}(p_0) = q_end`` for ``p_0`` by Newton's method with a
finite-difference Jacobian (``n + 1`` marches an iteration). The fixed-endpoint problem can have
several solutions (a pendulum that swings once or twice between the same positions); shooting
from the straight line's momentum picks the one the march from that momentum reaches, which
the straight-line start, a trajectory that never turns, can miss.
"""

from __future__ import annotations

import numpy as np

from ..discrete.scheme import Scheme
from ..physics.hamiltonian import site_density_weight_function
from .bvp_assembly import NodeLayout
from .bvp_phase import Request, run_phase

SHOOTING_ITERATIONS = 30


def straight_line(request: Request, times) -> dict:
    """Uniform motion between the endpoints: ``q`` linear in ``t``, ``p`` its slope (the
    velocity; for ``H = p^2/2 + V`` the momentum of that motion)."""
    s = (times - times[0]) / (times[-1] - times[0])
    q = request.q_start[None, :] + s[:, None] * (request.q_end - request.q_start)[None, :]
    slope = (request.q_end - request.q_start) / (times[-1] - times[0])
    return {"t": np.asarray(times, float), "q": q, "p": np.repeat(slope[None, :], times.size, 0)}


def fixed_scheme(scheme: Scheme) -> Scheme:
    return Scheme("fixed", alpha=scheme.alpha, clock=scheme.clock)


def start_point(request: Request, guess) -> dict:
    """The point the final solve starts from (module docstring); every phase that fails leaves
    the previous phase's point. ``guess`` is ``"straight"``, ``"march"`` or node arrays."""
    if isinstance(guess, dict):
        return guess
    uniform = request.grid_times if not request.scheme.variable_steps else \
        np.linspace(request.t0, request.t1, request.nodes)
    start = straight_line(request, uniform)
    fixed = fixed_scheme(request.scheme)
    if guess == "march":
        shot = shooting(request, fixed, uniform)
        if shot is not None:
            start = shot
    solver = "ipopt" if request.solver == "ipopt" else "newton"
    if guess != "march" or not request.scheme.variable_steps:
        solved = _solve_fixed(request, fixed, uniform, start, "fixed steps, uniform times",
                              solver)
        start = solved or start
    if not request.scheme.variable_steps:
        return start
    times = predicted_times(request.system, start["t"], start["q"], start["p"], request.theta)
    moved = {"t": times, "q": interpolate(times, start["t"], start["q"]),
             "p": interpolate(times, start["t"], start["p"])}
    return _solve_fixed(request, fixed, times, moved, "fixed steps, predicted times",
                        solver) or start


def _solve_fixed(request, fixed, times, start, name, solver):
    layout = NodeLayout(request.system.n, request.nodes)
    x, phase = run_phase(request, fixed, layout.pack(times, start["q"], start["p"]), name,
                         solver, times=times)
    if not (phase["converged"] and np.all(np.isfinite(x))):
        return None
    t, q, p = layout.unpack(x)
    return {"t": t, "q": q, "p": p}


def shooting(request: Request, fixed: Scheme, times) -> dict | None:
    """The march of ``fixed`` steps from ``(q_start, p_0)`` that ends on ``q_end`` (module
    docstring), or ``None`` if the iteration does not reach it to ``tol``."""
    from .march import march

    h = (request.t1 - request.t0) / (request.nodes - 1)

    params = dict(zip(request.system.params, request.theta.tolist(), strict=True))

    def shoot(p0):
        return march(request.system, request.q_start, p0, tau0=h, t_end=request.t1,
                     t0=request.t0, scheme=fixed, params=params, max_steps=request.nodes,
                     tol=min(request.tol, 1e-10))

    p0 = straight_line(request, times)["p"][0]
    record = {"phase": "shooting (march)", "solver": "newton (finite differences)",
              "converged": False, "return_status": "", "iterations": 0}
    request.phases.append(record)
    for iteration in range(1, SHOOTING_ITERATIONS + 1):
        run = shoot(p0)
        if not run.success or run.t.size != request.nodes:
            record["return_status"] = f"the march from p_0 = {p0.tolist()} failed: {run.message}"
            return None
        miss = run.q[-1] - request.q_end
        record["iterations"] = iteration
        if np.max(np.abs(miss)) <= request.tol:
            record.update(converged=True, return_status=f"q_end reached, p_0 = {p0.tolist()}")
            return {"t": run.t, "q": run.q, "p": run.p}
        step = _shooting_step(shoot, p0, run.q[-1], miss)
        if step is None:
            record["return_status"] = "a march of the finite differences failed"
            return None
        p0 = p0 - step
    record["return_status"] = f"q_end not reached in {SHOOTING_ITERATIONS} iterations"
    return None


def _shooting_step(shoot, p0, q_last, miss) -> np.ndarray | None:
    """Newton step ``J^-1 miss`` on ``q_{N-1}(p_0)``, ``J`` by forward differences, its length
    capped at ``max(1, |p_0|)``; ``None`` if a march fails."""
    n = p0.size
    J = np.empty((n, n))
    for i in range(n):
        h = 1e-7 * max(1.0, abs(p0[i]))
        bumped = p0.copy()
        bumped[i] += h
        run = shoot(bumped)
        if not run.success:
            return None
        J[:, i] = (run.q[-1] - q_last) / h
    step = np.linalg.lstsq(J, miss, rcond=None)[0]
    # a step larger than the momentum itself leaves the march's basin: cap it
    scale = max(1.0, float(np.max(np.abs(p0))))
    return step * min(1.0, scale / max(float(np.max(np.abs(step))), 1e-300))


def interpolate(times, t, values) -> np.ndarray:
    return np.column_stack([np.interp(times, t, column) for column in values.T])


def predicted_times(system, t, q, p, theta) -> np.ndarray:
    """Node times with the site density of the energy rules, ``tau_k ~ w^(-1/3)`` evaluated at
    the interval midpoints of the grid ``t``, ``q``, ``p``; same first and last time."""
    N = t.size
    w = np.asarray(site_density_weight_function(system).map(N - 1)(
        ((q[:-1] + q[1:]) / 2).T, ((p[:-1] + p[1:]) / 2).T, ((t[:-1] + t[1:]) / 2)[None, :],
        np.asarray(theta, float)[:, None])).ravel()
    # Where w <= 0 the energy rules have no positive step anyway (docs/theory.md
    # section 7); keep the prediction finite there and let the solve report it.
    floor = 1e-3 * np.median(np.abs(w)) if np.any(w != 0) else 1.0
    tau = np.maximum(w, floor) ** (-1 / 3)
    tau *= (t[-1] - t[0]) / tau.sum()
    times = t[0] + np.concatenate([[0.0], np.cumsum(tau)])
    times[-1] = t[-1]
    return times
