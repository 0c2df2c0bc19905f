"""Writing a run to a folder: ``result.npz``, ``meta.json`` and a plot."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..discrete import equations
from ..discrete.scheme import Scheme
from ..errors import InputError
from ..scenes import BoundaryConfig, RunConfig, Scene
from ..solution import Solution, Status


def prepare_folder(out: str | os.PathLike) -> Path:
    """Create ``out`` and check that it can be written, before any solve starts."""
    path = Path(out)
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / ".ddvp_write_test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise InputError(f"output folder {str(out)!r} cannot be written: {exc.strerror}") from None
    return path


def energy_report(scene: Scene, scheme: Scheme, solution: Solution, theta) -> dict:
    """The energy figures of a run.

    Autonomous ``H``: ``energy_error`` is the largest drift of the interval energy
    ``H(Q_k, P_k)`` (the quantity the energy rules conserve) from the first interval's;
    ``node_energy_drift`` the same for ``H(q_k, p_k)``. Time-dependent ``H``: ``energy_error`` is
    the largest residual of the energy equation (for ``fixed`` steps, of the ``lee`` balance).
    """
    system = scene.system
    report = {"energy_residual_max": _max_abs(solution.energy_residual)}
    if system.time_dependent:
        report["energy_error"] = report["energy_residual_max"]
        rule = equations.diagnostic_rule(scheme)
        report["energy_error_kind"] = f"largest residual of the {rule} energy equation"
        return report
    interval = equations.interval_energies(system, scheme, solution.t, solution.q, solution.p,
                                           theta)
    nodes = system.energy(solution.q, solution.p, solution.t, theta)
    report["energy_error"] = _max_abs(interval - interval[0]) if interval.size else 0.0
    report["energy_error_kind"] = ("largest drift of the interval energy E_k = v_k.dL/dv - L_k"
                                   if system.lagrangian_form else
                                   "largest drift of the interval energy H(Q_k, P_k)")
    report["node_energy_drift"] = _max_abs(nodes - nodes[0])
    return report


def _max_abs(values) -> float:
    values = np.asarray(values)
    return float(np.max(np.abs(values))) if values.size else 0.0


def write_run(out: Path, *, command: str, scene: Scene, config: RunConfig | BoundaryConfig,
              scheme: Scheme,
              solution: Solution, extra: dict | None = None, plot: bool = True) -> dict:
    """Write ``result.npz``, ``meta.json`` and ``trajectory.png``; return the metadata."""
    theta = scene.system.parameter_vector(config.params)
    arrays = {"t": solution.t, "q": solution.q, "p": solution.p,
              "energy_residual": solution.energy_residual,
              "canonical_residual": solution.canonical_residual}
    if solution.solvability.size:
        arrays["solvability"] = solution.solvability
    flagged = solution.stats.get("least_squares") or []
    if flagged:
        arrays["least_squares_step"] = np.array([e["step"] for e in flagged], dtype=int)
        arrays["least_squares_defect"] = np.array([e["energy_defect"] for e in flagged])
    np.savez(out / "result.npz", **arrays)
    tau = solution.tau
    meta = {
        "command": command,
        "scene": scene.name,
        "scheme": scheme.rule,
        "alpha": scheme.alpha,
        "clock": scheme.clock,
        "params": config.as_dict(),
        "status": solution.status.code,
        "success": solution.success,
        "message": solution.message,
        "steps": solution.steps,
        "t_reached": float(solution.t[-1]),
        "tau_min": float(tau.min()) if tau.size else None,
        "tau_max": float(tau.max()) if tau.size else None,
        "newton_iterations": solution.newton_iterations,
        "canonical_residual_max": _max_abs(solution.canonical_residual),
        "timing": solution.timing,
        **energy_report(scene, scheme, solution, theta),
    }
    if scene.invariants and solution.t.size:
        meta["invariant_drift"] = {
            name: _max_abs(f(solution.q, solution.p, **config.params)
                           - f(solution.q[:1], solution.p[:1], **config.params)[0])
            for name, f in scene.invariants.items()}
    if scene.exact is not None and solution.t.size:
        # The exact solution through the result's own first node (for a march: its initial
        # state; for a fixed-endpoint problem: the computed initial momentum).
        q, p = scene.exact(solution.t, solution.q[0], solution.p[0], solution.t[0],
                           **config.params)
        meta["error_vs_exact"] = float(max(_max_abs(solution.q - q), _max_abs(solution.p - p)))
    if solution.stats.get("solvability_warning"):
        meta["solvability_warning"] = solution.stats["solvability_warning"]
    if flagged:
        meta["least_squares_steps"] = len(flagged)
        meta["least_squares_defect_max"] = _max_abs([e["energy_defect"] for e in flagged])
    meta.update(extra or {})
    (out / "meta.json").write_text(json.dumps(meta, indent=2, default=_json_default) + "\n")
    if plot and solution.t.size >= 2:
        from .plotting import plot_trajectory
        plot_trajectory(solution, scene, scheme, theta, out / "trajectory.png")
    return meta


def write_higher_run(out: Path, *, command: str, scene, config: dict, solution: Solution,
                     plot: bool = True) -> dict:
    """``result.npz``, ``meta.json`` and ``trajectory.png`` of a higher-order run: ``p`` is the
    multiplier ``lambda_1``, ``energy`` the energy ``E^(k)`` where the recursion defines it."""
    energy = np.asarray(solution.stats.get("energy", np.zeros(0)))
    np.savez(out / "result.npz", t=solution.t, q=solution.q, p=solution.p, energy=energy)
    tau = solution.tau
    exact = scene._exact(solution.t, config["params"])
    meta = {"command": command, "scene": scene.name, "scheme": solution.scheme,
            "order": scene.order, "params": {**config["params"], "t0": config["t0"],
                                             "tau0": config["tau0"], "t_end": config["t_end"]},
            "status": solution.status.code, "success": solution.success,
            "message": solution.message, "steps": solution.steps,
            "t_reached": float(solution.t[-1]),
            "tau_min": float(tau.min()) if tau.size else None,
            "tau_max": float(tau.max()) if tau.size else None,
            "energy_error": float(np.ptp(energy)) if energy.size else 0.0,
            "energy_error_kind": "spread of E^(k) = sum_m lambda_m . v_m - L over the run",
            "error_vs_exact": float(np.max(np.abs(solution.q - exact))),
            "timing": solution.timing}
    (out / "meta.json").write_text(json.dumps(meta, indent=2, default=_json_default) + "\n")
    if plot and solution.t.size >= 2:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        panels = 3 if energy.size else 2
        fig, axes = plt.subplots(panels, 1, figsize=(8, 2.6 * panels), sharex=True)
        axes[0].plot(solution.t, solution.q, ".-", ms=3, label="nodes")
        axes[0].plot(solution.t, exact, "k--", lw=0.8, label="exact")
        axes[0].set_ylabel("q")
        axes[0].legend(fontsize=8)
        axes[1].plot(solution.t[:-1], tau, ".-", ms=3)
        axes[1].set_ylabel("tau_k")
        if energy.size:
            lo = scene.order - 1
            axes[2].plot(solution.t[lo:lo + energy.size], energy - energy[0], ".-", ms=3)
            axes[2].set_ylabel("E^(k) - E^(l-1)")
        axes[-1].set_xlabel("t")
        fig.suptitle(f"{scene.name} {command} [{solution.scheme}]: {solution.status.code}")
        fig.tight_layout()
        fig.savefig(out / "trajectory.png", dpi=110)
        plt.close(fig)
    return meta


def _json_default(value):
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Status):
        return value.code
    raise TypeError(f"cannot write {type(value).__name__} to JSON")
