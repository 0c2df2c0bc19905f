"""Measurements of the paper's claims (sections 3-5), each a function returning numbers.

``ddvp reproduce`` (``studies/reproduce.py``) turns them into figures and a report; the tests call
them at sizes that fit CI. Nothing here decides whether a claim holds: the report compares each
measured number with a threshold it states.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..discrete import Scheme, canonical_function, interval_action_expression
from ..physics import HamiltonianSystem, site_density_weight_function, vector_field_function
from ..scenes import load_scene
from ..solvers import StepControl, march


def dominant_period(t, values, *, longer_than=None, shorter_than=None) -> float:
    """Period of the strongest spectral line of ``values(t)`` (non-uniform ``t``) within the
    given band, from a zero-padded, Hann-windowed FFT with parabolic refinement of the peak."""
    t = np.asarray(t, float)
    step = float(np.mean(np.diff(t)))
    grid = np.arange(t[0], t[-1], step)
    signal = np.interp(grid, t, values)
    signal = (signal - signal.mean()) * np.hanning(grid.size)
    size = 8 * grid.size
    spectrum = np.abs(np.fft.rfft(signal, size))
    frequency = np.fft.rfftfreq(size, step)
    band = frequency > 0
    if longer_than is not None:
        band &= frequency < 1 / longer_than
    if shorter_than is not None:
        band &= frequency > 1 / shorter_than
    index = int(np.flatnonzero(band)[np.argmax(spectrum[band])])
    a, b, c = np.log(spectrum[index - 1:index + 2] + 1e-300)
    shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
    return float(1 / (frequency[index] + shift * (frequency[1] - frequency[0])))


def minima_spacing(t, values) -> tuple[float, int]:
    """Mean spacing of the strict local minima of ``values(t)`` (first to last over their count
    less one) and their count: the period of an oscillation whose spectrum has no single line
    (the step length of section 5, whose fast oscillation is modulated by the slow one into a
    comb of sidebands, none of them the oscillation's own period)."""
    t = np.asarray(t, float)
    values = np.asarray(values, float)
    inner = np.arange(1, values.size - 1)
    minima = inner[(values[inner] < values[inner - 1]) & (values[inner] < values[inner + 1])]
    if minima.size < 2:
        return float("nan"), int(minima.size)
    return float((t[minima[-1]] - t[minima[0]]) / (minima.size - 1)), int(minima.size)


def oscillation_period(t, q) -> float:
    """Mean period of ``q(t)`` from its upward zero crossings (linear interpolation)."""
    q = np.asarray(q, float)
    up = np.flatnonzero((q[:-1] < 0) & (q[1:] >= 0))
    crossings = t[up] - q[up] * (t[up + 1] - t[up]) / (q[up + 1] - q[up])
    return float(np.mean(np.diff(crossings)))


def step_extremes(t, q, tau) -> dict:
    """Where in the swing the locally smallest and largest steps fall: ``|q|`` at the interval
    midpoint over the swing's amplitude, averaged over the local minima and maxima of ``tau``."""
    middle = (q[:-1] + q[1:]) / 2
    amplitude = np.max(np.abs(q))
    inner = np.arange(1, tau.size - 1)
    minima = inner[(tau[inner] < tau[inner - 1]) & (tau[inner] < tau[inner + 1])]
    maxima = inner[(tau[inner] > tau[inner - 1]) & (tau[inner] > tau[inner + 1])]
    return {"at_smallest_steps": float(np.mean(np.abs(middle[minima])) / amplitude),
            "at_largest_steps": float(np.mean(np.abs(middle[maxima])) / amplitude),
            "minima": int(minima.size), "maxima": int(maxima.size)}


def paper_example(t_end: float = 10000.0) -> dict:
    """Section 5: the perturbed pendulum from the paper's data; its step-length periods and where
    the extreme steps fall (first 16 time units, as in figure 3)."""
    scene = load_scene("paper_pendulum")
    config = scene.resolve({"t_end": t_end})
    solution = march(
        scene.system,
        config.q0,
        config.p0,
        (0.0, config.t_end),
        tau0=config.tau0,
        params=config.params,
    )
    t, q, tau = solution.t, solution.q[:, 0], solution.tau
    first = t[:-1] <= 16.0
    # the step length's short period: the spacing of its minima (one per passage through
    # theta = 0); its spectrum below period 50 is a comb of sidebands 2 pi / 0.02 apart in
    # period, whose strongest line (3.449 at t_end = 1e4) is not the oscillation's period (3.304)
    short_period, minima = minima_spacing((t[:-1] + t[1:]) / 2, tau)
    result = {"solution": solution, "steps": solution.steps,
              "tau_range": (float(tau.min()), float(tau.max())),
              "pendulum_period": oscillation_period(t, q),
              "short_period": short_period, "short_minima": minima,
              "short_spectral_line": dominant_period(t[:-1], tau, shorter_than=50.0),
              "extremes": step_extremes(t[:np.count_nonzero(first) + 1],
                                        q[:np.count_nonzero(first) + 1], tau[first])}
    if t_end >= 2000:
        result["long_period"] = dominant_period(t[:-1], tau, longer_than=50.0)
    return result


def quartic_system() -> HamiltonianSystem:
    """``H = p^2/2 + q^2/2 + q^4/4``: a second potential with ``V''' != 0``."""
    return HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 + q[0] ** 2 / 2 + q[0] ** 4 / 4, n=1,
                             name="quartic")


def site_density_spread(system: HamiltonianSystem, q0, p0, tau0s, *, t_end: float) -> dict:
    """Section 4: ``tau_k (V'' p^2 + V'^2)^(1/3)`` (the weight ``f' H_zz f``) along ``vddvp``
    marches, its spread ``max/min - 1`` for each ``tau0`` and the fitted slope of log(spread)
    against log(tau0). The weight is taken at node ``k`` (``"node"``) and at the midpoint of
    interval ``k`` (``"midpoint"``); the paper says constant up to O(tau)."""
    weight = site_density_weight_function(system)
    result = {"tau0": list(tau0s), "tau_spread": [], "node": [], "midpoint": []}
    for tau0 in tau0s:
        solution = march(system, q0, p0, (0.0, t_end), tau0=tau0)
        N = solution.t.size
        nodes = np.asarray(weight.map(N)(solution.q.T, solution.p.T, solution.t[None, :],
                                         np.zeros((0, 1)))).ravel()
        middle = np.asarray(weight.map(N - 1)(
            ((solution.q[:-1] + solution.q[1:]) / 2).T, ((solution.p[:-1] + solution.p[1:]) / 2).T,
            ((solution.t[:-1] + solution.t[1:]) / 2)[None, :], np.zeros((0, 1)))).ravel()
        for key, w in (("node", nodes[:-1]), ("midpoint", middle)):
            product = solution.tau * np.cbrt(w)
            result[key].append(float(product.max() / product.min() - 1))
        result["tau_spread"].append(float(solution.tau.max() / solution.tau.min() - 1))
    for key in ("node", "midpoint"):
        result[f"slope_{key}"] = float(np.polyfit(np.log(tau0s), np.log(result[key]), 1)[0])
    return result


def gauge_differences(t_end: float = 100.0) -> dict:
    """Section 3's remark: add ``f(t) = 0.05 sin(t/2) + 0.01 t`` to the paper's ``H``; the largest
    change of the node times and angles under each rule."""
    base = load_scene("paper_pendulum")
    gauged = HamiltonianSystem(
        lambda q, p, t, eps, omega: base.hamiltonian(q, p, t, eps, omega)
        + 0.05 * ca.sin(0.5 * t) + 0.01 * t, n=1, params=dict(base.params), name="gauged")
    result = {}
    for rule in ("vddvp", "lee"):
        a = march(base.system, [0.5], [0.5], (0.0, t_end), tau0=0.5, scheme=rule)
        b = march(gauged, [0.5], [0.5], (0.0, t_end), tau0=0.5, scheme=rule)
        n = min(a.t.size, b.t.size)
        result[rule] = {"t": float(np.max(np.abs(a.t[:n] - b.t[:n]))),
                        "q": float(np.max(np.abs(a.q[:n] - b.q[:n]))),
                        "steps": (a.steps, b.steps), "success": a.success and b.success}
    return result


def step_ratio_sweep(tau0s, *, t_end: float = 16.0) -> dict:
    """Section 4 on explicit time dependence: the range of ``tau/tau0`` on the paper's example
    for each ``tau0`` under ``vddvp`` and ``lee``."""
    scene = load_scene("paper_pendulum")
    rows = []
    for rule in ("vddvp", "lee"):
        for tau0 in tau0s:
            solution = march(scene.system, [0.5], [0.5], (0.0, t_end), tau0=tau0, scheme=rule)
            ratio = solution.tau / tau0
            rows.append({"rule": rule, "tau0": tau0, "status": solution.status.code,
                         "steps": solution.steps, "t_reached": float(solution.t[-1]),
                         "ratio_min": float(ratio.min()), "ratio_max": float(ratio.max())})
    return {"rows": rows}


def _symplectic_defect(M, n_coordinates):
    """``max |M' J M - J| / max(1, |M|^2)`` with ``J = [[0, I], [-I, 0]]`` on ``n_coordinates``
    pairs: relative to the size of the products it is made of, so round-off reads ~1e-16 even
    where the map stretches (the energy equation's O(tau) conditioning makes ``dt'/dE`` large)."""
    m = n_coordinates
    J = np.block([[np.zeros((m, m)), np.eye(m)], [-np.eye(m), np.zeros((m, m))]])
    scale = max(1.0, float(np.max(np.abs(M))) ** 2)
    return float(np.max(np.abs(M.T @ J @ M - J)) / scale)


def fixed_step_map(system: HamiltonianSystem, scheme: Scheme):
    """``(z, t, tau, theta) -> z'``: one step of the canonical equations with a given step, through
    CasADi's Newton rootfinder (differentiable by the implicit function theorem)."""
    n = system.n
    z, z_next = ca.MX.sym("z", 2 * n), ca.MX.sym("z_next", 2 * n)
    t, tau = ca.MX.sym("t"), ca.MX.sym("tau")
    theta = ca.MX.sym("theta", system.theta.numel())
    canonical = canonical_function(system, scheme)
    g = ca.Function("g", [z_next, ca.vertcat(z, t, tau, theta)],
                    [canonical(t, t + tau, z[:n], z[n:], z_next[:n], z_next[n:], theta)])
    root = ca.rootfinder("step", "newton", g, {"abstol": 1e-15, "show_eval_warnings": False})
    z_out = root(z, ca.vertcat(z, t, tau, theta))
    return ca.Function("fixed_step_map", [z, t, tau, theta],
                       [z_out, ca.jacobian(z_out, z)])


def extended_lee_map(system: HamiltonianSystem, scheme: Scheme):
    """``(q, t, p, -E, guess, theta) -> (q', t', p', -E')`` and its Jacobian: one ``lee`` step as
    a map of the extended phase space; also ``after(x, step, theta)``, the image of ``x`` for a
    given step ``(q', p', tau)`` (it does not depend on ``E``). ``E_k = -dS_{k-1}/dt_k`` is the
    energy that step k must match (``dS_k/dt_k = E_k``, the node equation ``dS_D/dt_k = 0``);
    the step hands on ``E_{k+1} = -dS_k/dt_{k+1}``. Both derivatives by automatic
    differentiation of the interval action."""
    n = system.n
    x = ca.SX.sym("x", 2 * n + 2)  # (q, t, p, -E)
    q, t, p, minus_E = x[:n], x[n], x[n + 1:2 * n + 1], x[2 * n + 1]
    unknown = ca.SX.sym("unknown", 2 * n + 1)  # (q', p', tau)
    q_next, p_next, tau = unknown[:n], unknown[n:2 * n], unknown[2 * n]
    t_a, t_b = ca.SX.sym("t_a"), ca.SX.sym("t_b")
    theta = ca.SX.sym("theta", system.theta.numel())
    action = interval_action_expression(system, scheme, t_a, t_b, q, p, q_next, p_next,
                                                  theta)
    dS = ca.Function("dS", [t_a, t_b, x, unknown, theta],
                     [ca.gradient(action, t_a), ca.gradient(action, t_b)])
    dS_left, dS_right = dS(t, t + tau, x, unknown, theta)
    canonical = canonical_function(system, scheme)(
        t, t + tau, q, p, q_next, p_next, theta)
    g = ca.Function("g", [unknown, ca.vertcat(x, theta)],
                    [ca.vertcat(canonical, dS_left + minus_E)])
    root = ca.rootfinder("lee_step", "newton", g, {"abstol": 1e-15,
                                                   "show_eval_warnings": False})
    X = ca.MX.sym("X", 2 * n + 2)
    Theta = ca.MX.sym("Theta", system.theta.numel())
    Guess = ca.MX.sym("Guess", 2 * n + 1)
    solved = root(Guess, ca.vertcat(X, Theta))
    after = ca.Function("after", [x, unknown, theta],
                        [ca.vertcat(q_next, t + tau, p_next, dS_right)])
    image = after(X, solved, Theta)
    return (ca.Function("extended_lee_map", [X, Guess, Theta], [image, ca.jacobian(image, X)]),
            after)


def symplecticity(samples: int = 5) -> dict:
    """Section 3's claim: the schemes are symplectic. ``max |M' J M - J|`` of the one-step map's
    Jacobian (automatic differentiation through the rootfinder) at ``samples`` nodes of a march,
    for fixed steps in phase space and for the ``lee`` step in the extended phase space
    ``(q, t; p, -E)``, on the autonomous pendulum and the paper's time-dependent example."""
    scheme = Scheme()
    result = {}
    for name in ("pendulum", "paper_pendulum"):
        scene = load_scene(name)
        system = scene.system
        theta = system.parameter_vector()
        run = march(system, [0.5], [0.5], (0.0, 20.0), tau0=0.1, scheme="lee")
        picks = np.linspace(1, run.steps - 1, samples).astype(int)
        fixed = fixed_step_map(system, scheme)
        extended, after_step = extended_lee_map(system, scheme)
        defects_fixed, defects_extended = [], []
        for k in picks:
            z = np.concatenate([run.q[k], run.p[k]])
            _, M = fixed(z, run.t[k], 0.1, theta)
            defects_fixed.append(_symplectic_defect(np.asarray(M), system.n))
            # -E_k = dS_{k-1}/dt_k: what the march's previous step hands on
            x_prev = np.concatenate([run.q[k - 1], [run.t[k - 1]], run.p[k - 1], [0.0]])
            step = np.concatenate([run.q[k], run.p[k], [run.t[k] - run.t[k - 1]]])
            minus_E = float(np.asarray(after_step(x_prev, step, theta)).ravel()[-1])
            x = np.concatenate([run.q[k], [run.t[k]], run.p[k], [minus_E]])
            guess = np.concatenate([run.q[k + 1], run.p[k + 1], [run.t[k + 1] - run.t[k]]])
            after, M = extended(x, guess, theta)
            after = np.asarray(after).ravel()
            assert abs(after[system.n] - run.t[k + 1]) < 1e-9, "the map is not the march's step"
            defects_extended.append(_symplectic_defect(np.asarray(M), system.n + 1))
        # Negative control: explicit Euler, z' = z + tau f(z, t), is not symplectic.
        zs = ca.SX.sym("z", 2 * system.n)
        flow = vector_field_function(system)(zs, system.t, system.theta)
        euler = ca.Function("euler", [zs, system.t, system.theta],
                            [ca.jacobian(zs + 0.1 * flow, zs)])
        z = np.concatenate([run.q[picks[0]], run.p[picks[0]]])
        control = _symplectic_defect(np.asarray(euler(z, run.t[picks[0]], theta)), system.n)
        result[name] = {"time_dependent": system.time_dependent,
                        "fixed_phase_space": max(defects_fixed),
                        "lee_extended": max(defects_extended),
                        "explicit_euler_control": control}
    return result


def energy_residual_growth(steps=(1000, 10_000, 100_000)) -> dict:
    """The energy equation's residual along long ``vddvp`` runs of the paper's example: its
    largest value and the size of its running sum (what a drift of the energy level would be)
    after each number of steps."""
    scene = load_scene("paper_pendulum")
    # accuracy=None: what is measured is the scheme's own equation over many steps, not how
    # closely the steps follow the motion (the accuracy check stops this run as inaccurate after
    # 565441 steps, t = 3.3e5, short of the 1e6 the report asks)
    run = march(scene.system, [0.5], [0.5], (0.0, 1e12), tau0=0.5,
                steps=StepControl(max_steps=max(steps)), accuracy=None)
    if run.steps < max(steps):
        raise RuntimeError(f"the march stopped after {run.steps} of {max(steps)} steps: "
                           f"{run.status.code}: {run.message}")
    running = np.cumsum(run.energy_residual)
    rows = [{"steps": N, "t": float(run.t[N]),
             "max_residual": float(np.max(np.abs(run.energy_residual[:N - 1]))),
             "running_sum": float(np.max(np.abs(running[:N - 1])))} for N in steps]
    return {"rows": rows}


def legendre_agreement(t_end: float = 20.0) -> dict:
    """Section 3's discrete Legendre transform: the pendulum declared by ``L = v^2/2 - V``
    (``pendulum_lagrangian``) and by ``H = p^2/2 + V`` (``pendulum``) from the same
    ``(q0, p0, tau0)`` under each rule; the largest difference of their node times, angles and
    momenta (the two discrete trajectories are the same, so this is solver tolerance)."""
    hamiltonian, lagrangian = load_scene("pendulum"), load_scene("pendulum_lagrangian")
    result = {}
    for rule in ("vddvp", "lee", "fixed"):
        a = march(hamiltonian.system, [0.5], [0.5], (0.0, t_end), tau0=0.05, scheme=rule)
        b = march(lagrangian.system, [0.5], [0.5], (0.0, t_end), tau0=0.05, scheme=rule)
        n = min(a.t.size, b.t.size)
        result[rule] = {"t": float(np.max(np.abs(a.t[:n] - b.t[:n]))),
                        "q": float(np.max(np.abs(a.q[:n] - b.q[:n]))),
                        "p": float(np.max(np.abs(a.p[:n] - b.p[:n]))),
                        "steps": (a.steps, b.steps), "success": a.success and b.success}
    return result
