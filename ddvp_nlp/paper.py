"""Measurements of the paper's claims (sections 3-5), each a function returning numbers.

``ddvp reproduce`` (``report.py``) turns them into figures and a report; the tests call them at
sizes that fit CI. Nothing here decides whether a claim holds: the report sets the measured
number beside what the paper says.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from . import equations
from .march import march
from .scenes import load_scene
from .system import HamiltonianSystem


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
    solution = march(scene.system, config.q0, config.p0, tau0=config.tau0, t_end=config.t_end,
                     params=config.params)
    t, q, tau = solution.t, solution.q[:, 0], solution.tau
    first = t[:-1] <= 16.0
    result = {"solution": solution, "steps": solution.steps,
              "tau_range": (float(tau.min()), float(tau.max())),
              "pendulum_period": oscillation_period(t, q),
              "short_period": dominant_period(t[:-1], tau, shorter_than=50.0),
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
    weight = equations.site_density_weight_function(system)
    result = {"tau0": list(tau0s), "tau_spread": [], "node": [], "midpoint": []}
    for tau0 in tau0s:
        solution = march(system, q0, p0, tau0=tau0, t_end=t_end)
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
        a = march(base.system, [0.5], [0.5], tau0=0.5, t_end=t_end, scheme=rule)
        b = march(gauged, [0.5], [0.5], tau0=0.5, t_end=t_end, scheme=rule)
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
            solution = march(scene.system, [0.5], [0.5], tau0=tau0, t_end=t_end, scheme=rule)
            ratio = solution.tau / tau0
            rows.append({"rule": rule, "tau0": tau0, "status": solution.status.code,
                         "steps": solution.steps, "t_reached": float(solution.t[-1]),
                         "ratio_min": float(ratio.min()), "ratio_max": float(ratio.max())})
    return {"rows": rows}
