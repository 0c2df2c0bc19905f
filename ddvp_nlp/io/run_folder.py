"""Writing a run to a folder: ``result.npz``, ``meta.json`` and a plot, for every kind of scene
(Hamiltonian, first-order Lagrangian, higher-order Lagrangian), and reading it back.

The files are written to temporary names and renamed into place under the folder's lock
(`ddvp_nlp.io.atomic`), ``meta.json`` last; ``meta.json`` records what it describes (the
node count and the SHA-256 of ``result.npz``), so `read_run` refuses a pair that a kill
between two renames, or an older tool, left mismatched. A long march also writes the same pair
as a checkpoint at intervals (`write_checkpoint`), with status ``running``.
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path

import numpy as np

from ..discrete import Scheme, diagnostic_rule, interval_energies
from ..errors import InputError
from ..scenes import BoundaryConfig, HigherOrderScene, RunConfig, Scene
from ..solution import Solution, Status
from . import atomic, figures


def settings_hash(settings: dict) -> str:
    """Eight hex digits of the SHA-256 of ``settings`` written as sorted JSON: equal settings
    give equal hashes, in any process."""
    import hashlib

    text = json.dumps(settings, sort_keys=True, default=json_default)
    return hashlib.sha256(text.encode()).hexdigest()[:8]


def default_folder(label: str, resolved: dict, overrides: dict) -> str:
    """A run's default folder: ``runs/LABEL`` (``LABEL`` = ``SCENE-SCHEME``, or
    ``SCENE-bvp-SCHEME``) for the scene's own settings, ``runs/LABEL-HASH`` when ``overrides``
    changed any, ``HASH`` from the ``resolved`` settings, so that two runs with different
    settings never share a folder and the same settings always find theirs."""
    if not overrides:
        return f"runs/{label}"
    return f"runs/{label}-{settings_hash(resolved)}"


def run_energies(system, scheme: Scheme, solution: Solution, theta):
    """For autonomous ``H``: ``H(z_k)`` at every node and the interval energies; for a
    time-dependent one only ``H(z_0, t_0)`` (what its reports use). Computed once per run, for
    ``meta.json``'s figures and for the figure's energy panel."""
    if system.time_dependent:
        return system.energy(solution.q[:1], solution.p[:1], solution.t[:1], theta), None
    nodes = system.energy(solution.q, solution.p, solution.t, theta)
    if thinned(solution) or system.n_constraints:
        # the kept nodes are not consecutive: no interval between them; a constrained
        # interval's energy needs its multipliers (the march's energy residual says it)
        return nodes, None
    return nodes, interval_energies(system, scheme, solution.t, solution.q,
                                              solution.p, theta)


def energy_report(scene: Scene, scheme: Scheme, solution: Solution, theta, energies) -> dict:
    """The energy figures of a run.

    Autonomous ``H``: ``energy_error`` is the largest drift of the interval energy
    ``H(Q_k, P_k)`` (the quantity the energy rules conserve) from the first interval's;
    ``node_energy_drift`` the same for ``H(q_k, p_k)``. Time-dependent ``H``: ``energy_error`` is
    the largest residual of the energy equation (for ``fixed`` steps, of the ``lee`` balance).
    """
    system = scene.system
    report = {"energy_residual_max": _max_abs(solution.energy_residual)}
    nodes, interval = energies  # run_energies
    if system.time_dependent:
        report["H0"] = float(nodes[0]) if solution.t.size else float("nan")
        report["energy_error"] = report["energy_residual_max"]
        rule = diagnostic_rule(scheme)
        report["energy_error_kind"] = f"largest residual of the {rule} energy equation"
        return report
    report["H0"] = float(nodes[0])
    # relative to |H0| as the figure's panel is (max(1, |H0|) made it absolute in units where
    # |H0| < 1: 1e-32 for a drift of 1e-16 of a swing's energy in lengths of 1e-8); absolute,
    # and said so, where H0 is 0
    h0 = abs(float(nodes[0]))
    relative = h0 > 0 and np.isfinite(h0)
    report["node_energy_error"] = _max_abs(nodes - nodes[0]) / (h0 if relative else 1.0)
    report["node_energy_error_kind"] = "relative to |H0|" if relative else "absolute (H0 = 0)"
    kept = solution.march.kept if solution.march is not None else None
    if system.n_constraints:
        report["energy_error"] = report["energy_residual_max"]
        report["energy_error_kind"] = ("largest residual of the energy equation (a "
                                       "constrained interval's energy uses its own momenta)")
        report["node_energy_drift"] = _max_abs(nodes - nodes[0])
        return report
    if thinned(solution):
        # a thinned march keeps no consecutive intervals: its largest energy residual over
        # every step, which the march recomputed as it went (and H's drift at the kept nodes)
        report["energy_residual_max"] = kept["energy_residual_max"]
        report["energy_error"] = kept["energy_residual_max"]
        report["energy_error_kind"] = ("largest residual of the energy equation over every "
                                       "step (a thinned run keeps no consecutive intervals)")
        report["node_energy_drift"] = _max_abs(nodes - nodes[0])
        return report
    report["energy_error"] = _max_abs(interval - interval[0]) if interval.size else 0.0
    report["energy_error_kind"] = ("largest drift of the interval energy E_k = v_k.dL/dv - L_k"
                                   if system.lagrangian_form else
                                   "largest drift of the interval energy H(Q_k, P_k)")
    report["node_energy_drift"] = _max_abs(nodes - nodes[0])
    return report


def thinned(solution: Solution) -> bool:
    """Whether a march kept only some of its nodes (``Output(keep_every=k)``)."""
    kept = solution.march.kept if solution.march is not None else None
    return bool(kept) and (kept["keep_every"] > 1 or kept["keep"] != "nodes")


def _max_abs(values) -> float:
    values = np.asarray(values)
    return float(np.max(np.abs(values))) if values.size else 0.0


def _computed_max(values, steps: int) -> float | None:
    """The largest ``|value|``, or ``None`` where a run of ``steps`` steps has none computed
    (an interrupted run written without its residuals: 0.0 would read as residuals of 0)."""
    return None if steps and not np.size(values) else _max_abs(values)


def write_run(out: Path, *, command: str, scene: Scene | HigherOrderScene,
              config: RunConfig | BoundaryConfig | dict, solution: Solution,
              scheme: Scheme | None = None, extra: dict | None = None,
              plot: bool = True, interruptible=None, figure_format: str = "png") -> dict:
    """Write ``result.npz``, ``meta.json`` and ``trajectory.png`` (``.svg``, ``.pdf``: by
    ``figure_format``) of a run of any scene; return the metadata.

    A scene with ``H`` or a first-order ``L`` needs its ``scheme``. A higher-order scene's run
    (``config`` the dict of `HigherOrderScene.resolve`) stores ``p`` as the multiplier
    ``lambda_1`` and ``energy``, the energy ``E^(k)`` where the recursion defines it.
    ``interruptible``: as for `save_run`.
    """
    record = _higher_record if isinstance(scene, HigherOrderScene) else _first_order_record
    arrays, meta, draw = record(command, scene, config, scheme, solution, interruptible)
    meta.update(extra or {})
    if command == "bvp" and not solution.success and \
            solution.status not in (Status.INACCURATE, Status.DRIFTED):  # judged, not failed
        meta["note"] = NOT_A_SOLUTION
    figure = draw if plot and draw is not None and solution.t.size >= 2 else None
    if figure is not None:
        figure = functools.partial(figure, fmt=figures.check_format(figure_format))
    return save_run(out, arrays, meta, figure, interruptible=interruptible,
                    figure_format=figure_format)


RESULT, META, FIGURE = "result.npz", "meta.json", "trajectory"
NOT_A_SOLUTION = ("NOT A SOLUTION: the nodes are the last iterate of the failed solve, kept for "
                  "diagnosis; they do not satisfy the equations")


def save_run(out, arrays: dict, meta: dict, draw=None, *, interruptible=None,
             figure_format: str = "png") -> dict:
    """Write ``result.npz`` (``arrays``), ``trajectory.png`` (``draw(file)``, if given, in
    ``figure_format``; an older figure of any format is removed) and ``meta.json`` (``meta``
    with ``nodes``, ``result_sha256`` and the manifest of the files) as one set through the
    output layer (`ddvp_nlp.io.atomic`): all of them or none, ``meta.json`` last.
    Return the metadata written.

    ``interruptible``: a context inside which an interrupt may stop the figure (the figure is
    then left out and ``meta["figure"]`` says so; the nodes are written all the same).
    Raises `OutputError` naming the file that could not be written;
    the folder then still holds the earlier set whole (or nothing)."""
    with atomic.output_folder(out) as folder:
        result = folder.scratch(RESULT, lambda handle: np.savez(handle, **arrays))
        try:
            name = figures.file_name(FIGURE, figure_format)
            figure = figure_writer(folder, name, draw, interruptible)
            meta = {**meta, "nodes": int(np.asarray(arrays["t"]).size)}
            if draw is not None and figure is None:
                meta["figure"] = "not drawn: interrupted while drawing"
        except BaseException:
            folder.remove(result)
            raise
        return folder.commit({RESULT: result, **figures.other_formats(FIGURE, figure_format),
                              name: figure}, meta,
                             digests={"result_sha256": RESULT})


def figure_writer(folder, name: str, draw, interruptible=None):
    """The figure ``draw(file)`` written to a scratch file of ``folder`` for ``name`` (a
    `Written` a set takes), or ``None``: no figure, or an interrupt
    while it was drawn inside ``interruptible()`` (the rest of the set is written all the
    same)."""
    if draw is None:
        return None
    import contextlib

    try:
        with (interruptible or contextlib.nullcontext)():
            return folder.scratch(name, draw)
    except KeyboardInterrupt:
        return None


def write_checkpoint(out, *, command: str, scene_name: str, t, z, n: int,
                     extra: dict | None = None) -> dict:
    """The run so far, as a set like a finished run's (``t``, ``q``, ``p`` only; no figure),
    with status ``running``: what a kill of a long march leaves behind."""
    t = np.asarray(t)
    steps = max(t.size - 1, 0)
    meta = {"command": command, "scene": scene_name, "status": "running", "success": False,
            "message": f"checkpoint of a run still going (or killed) at step {steps}, "
                       f"t = {float(t[-1]):.10g}; not a solution of the whole problem",
            "steps": steps, "t_reached": float(t[-1]), **(extra or {})}
    return save_run(out, {"t": t, "q": z[:, :n], "p": z[:, n:]}, meta)


def read_run(folder: str | os.PathLike) -> tuple[dict, dict]:
    """``(arrays, meta)`` of a run folder's last complete set, after checking that
    ``meta.json`` describes the ``result.npz`` beside it (checksum, node count, shapes, finite
    increasing times). A kill between two renames leaves the previous set, which is read
    instead. Raises `InputError` naming the folder and the reason otherwise, and
    ``FolderBusy`` (an `InputError`) while another ddvp process writes the folder: the set is
    read under the folder's shared lock (`ddvp_nlp.io.atomic.reading`)."""
    folder = Path(folder)
    with atomic.reading(folder):  # no writer swaps the set while it is read
        return _read_run(folder)


def _read_run(folder: Path) -> tuple[dict, dict]:
    from ..validation import check_file_size

    meta, files = atomic.read_set(folder, required=(RESULT,))
    path = files[RESULT]
    check_file_size(str(path), path.stat().st_size)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except Exception as exc:  # zipfile, format and value errors of a damaged file
        raise InputError(f"{path} is not a result.npz ddvp wrote: {type(exc).__name__}: "
                         f"{exc}") from None
    check_run_arrays(str(path), arrays)
    if arrays["t"].size != meta.get("nodes"):
        raise InputError(f"{path} holds {arrays['t'].size} nodes, {folder / META} "
                         f"says {meta.get('nodes')}")
    return arrays, meta


def check_run_arrays(where: str, arrays: dict) -> None:
    """``t``, ``q``, ``p`` of a result: real, finite, ``t`` strictly increasing, ``q`` and
    ``p`` of shape ``(t.size, n)``."""
    missing = [name for name in ("t", "q", "p") if name not in arrays]
    if missing:
        raise InputError(f"{where} has no array {missing[0]!r} (it needs t, q and p)")
    t, q, p = arrays["t"], arrays["q"], arrays["p"]
    for name, value in (("t", t), ("q", q), ("p", p)):
        if value.dtype.kind not in "fiu":
            raise InputError(f"{where}: {name} must hold real numbers, got dtype {value.dtype}")
        if not np.all(np.isfinite(value)):
            raise InputError(f"{where}: {name} holds values that are not finite")
    if t.ndim == 1 and t.size >= 2 and np.all(np.diff(t) < 0):
        raise InputError(f"{where}: the run marched backwards (t decreasing); --resume and "
                         "--guess take a forward run")
    if t.ndim != 1 or t.size < 2 or np.any(np.diff(t) <= 0):
        raise InputError(f"{where}: t must be at least two strictly increasing times")
    if q.ndim != 2 or q.shape[0] != t.size or p.shape != q.shape or q.shape[1] < 1:
        raise InputError(f"{where}: q and p must have shape ({t.size}, n), got {q.shape} "
                         f"and {p.shape}")


def _steps_meta(solution: Solution) -> dict:
    """Status, steps and step range: the part of ``meta.json`` every kind of run has."""
    tau = solution.tau
    found = {"status": solution.status.code, "success": solution.success,
             "message": solution.message, "steps": solution.steps,
             "t_reached": float(solution.t[-1]),
             "tau_min": float(tau.min()) if tau.size else None,
             "tau_max": float(tau.max()) if tau.size else None}
    if thinned(solution):  # every step marched, not the intervals between kept nodes
        kept = solution.march.kept
        found.update(steps=kept["nodes_marched"] - 1, tau_min=kept["tau_min"],
                     tau_max=kept["tau_max"], kept_every=kept["keep_every"],
                     nodes_marched=kept["nodes_marched"], nodes_kept=kept["nodes_kept"])
    return found


def _optional(interruptible, compute, fallback):
    """``compute()``, or ``fallback`` when an interrupt stops it inside ``interruptible()``:
    the figures of a run that an interrupt may skip (the nodes are written all the same)."""
    import contextlib

    try:
        with (interruptible or contextlib.nullcontext)():
            return compute()
    except KeyboardInterrupt:
        return fallback


SKIPPED = ("not computed: the run was interrupted, and is written without it (the nodes in "
           "result.npz give it)")


def requested_arrays(solution: Solution) -> dict:
    """The states at the asked-for times (``t_eval``, ``z_eval``) and each event's crossings
    (``t_events_K``, ``z_events_K`` for event ``K``) of a march (``Output(t_eval=...,
    events=...)``), for ``result.npz``."""
    arrays = {}
    if solution.t_eval is not None:
        arrays["t_eval"], arrays["z_eval"] = solution.t_eval, solution.z_eval
    for k, (times, states) in enumerate(zip(solution.t_events or (), solution.z_events or (),
                                            strict=True)):
        arrays[f"t_events_{k}"], arrays[f"z_events_{k}"] = times, states
    return arrays


def _first_order_record(command, scene: Scene, config, scheme: Scheme, solution: Solution,
                        interruptible=None):
    """Arrays, metadata and figure of a run of a scene with ``H`` or a first-order ``L``; the
    energies, the scene's checks and the figure may be cut by an interrupt (``SKIPPED``)."""
    theta = scene.system.parameter_vector(config.params)
    arrays = {"t": solution.t, "q": solution.q, "p": solution.p,
              "energy_residual": solution.energy_residual,
              "canonical_residual": solution.canonical_residual}
    if solution.solvability.size:
        arrays["solvability"] = solution.solvability
    arrays.update(requested_arrays(solution))
    flagged = solution.march.least_squares if solution.march is not None else []
    if flagged:
        arrays["least_squares_step"] = np.array([e["step"] for e in flagged], dtype=int)
        arrays["least_squares_defect"] = np.array([e["energy_defect"] for e in flagged])
    energies = _optional(interruptible,
                         lambda: run_energies(scene.system, scheme, solution, theta), None)
    energy = energy_report(scene, scheme, solution, theta, energies) if energies else {
        "energy_residual_max": _computed_max(solution.energy_residual, solution.steps),
        "energy_error": float("nan"), "energy_error_kind": SKIPPED}
    meta = {"command": command, "scene": scene.name, "scheme": scheme.rule,
            "alpha": scheme.alpha, "clock": scheme.clock, "params": config.as_dict(),
            **_steps_meta(solution),
            "newton_iterations": solution.newton_iterations,
            "canonical_residual_max": _computed_max(solution.canonical_residual,
                                                    solution.steps),
            "timing": solution.timing,
            **energy,
            **_optional(interruptible, lambda: _checks(scene, config, solution),
                        {"checks": SKIPPED})}
    if solution.verdict is not None:
        meta["accuracy"] = solution.verdict.as_dict()
        arrays["local_error"] = solution.local_error
    if flagged:
        meta["least_squares_steps"] = len(flagged)
        meta["least_squares_defect_max"] = _max_abs([e["energy_defect"] for e in flagged])

    def draw(path, fmt="png"):
        from .run_figure import plot_trajectory
        plot_trajectory(solution, scene, scheme, path, energies=energies, fmt=fmt,
                        fixed_ends=command == "bvp")

    return arrays, meta, draw if energies else None


def _checks(scene: Scene, config, solution: Solution) -> dict:
    """Invariant drifts, the error against an exact solution, a solvability warning. A
    scene's function that fails on the run's nodes (it was checked on the start when the
    scene was loaded) is recorded as such; the nodes are written all the same."""
    from ..scenes.guard import check_invariant_value

    found = {}
    if scene.invariants and solution.t.size:
        drift = {}
        for name, f in scene.invariants.items():
            try:
                values = check_invariant_value(scene.name, name,
                                               f(solution.q, solution.p, **config.params),
                                               solution.t.size)
                drift[name] = _max_abs(values - values[0])
            except InputError as exc:
                drift[name] = f"not computed: {exc}"
        found["invariant_drift"] = drift
    if scene.exact is not None and solution.t.size:
        # The exact solution through the result's own first node (for a march: its initial
        # state; for a fixed-endpoint problem: the computed initial momentum).
        try:
            q, p = scene.exact(solution.t, solution.q[0], solution.p[0], solution.t[0],
                               **config.params)
            error = max(_max_abs(solution.q - np.asarray(q, dtype=float)),
                        _max_abs(solution.p - np.asarray(p, dtype=float)))
        except (ValueError, TypeError) as reason:  # a start it does not cover, or a failure
            found["exact_solution"] = f"not compared: {reason}"
        else:
            found["error_vs_exact"] = float(error)
    if solution.march is not None and solution.march.solvability_warning:
        found["solvability_warning"] = solution.march.solvability_warning
    return found


def _higher_record(command, scene: HigherOrderScene, config: dict, scheme, solution: Solution,
                   interruptible=None):
    """Arrays, metadata and figure of a run of a scene with higher derivatives."""
    energy = np.asarray(solution.higher.energy if solution.higher else np.zeros(0))
    exact = scene.exact_motion(solution.t, config.params)
    meta = {"command": command, "scene": scene.name, "scheme": solution.scheme,
            "order": scene.order, "params": {**config.params, "t0": config.t0,
                                             "tau0": config.tau0, "t_end": config.t_end},
            **_steps_meta(solution),
            "energy_error": float(np.ptp(energy)) if energy.size else 0.0,
            "energy_error_kind": "spread of E^(k) = sum_m lambda_m . v_m - L over the run",
            "error_vs_exact": float(np.max(np.abs(solution.q - exact))),
            "timing": solution.timing}
    if solution.verdict is not None:
        meta["accuracy"] = solution.verdict.as_dict()

    def draw(path, fmt="png"):
        from .run_figure import plot_higher_trajectory
        plot_higher_trajectory(solution, scene, command, exact, energy, path, fmt)

    return {"t": solution.t, "q": solution.q, "p": solution.p, "energy": energy}, meta, draw


def json_default(value):
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Status):
        return value.code
    raise TypeError(f"cannot write {type(value).__name__} to JSON")


def read_guess(value: str, n: int | None = None):
    """``straight``, ``march``, or the ``t``, ``q``, ``p`` of a run folder's last complete
    set, or of a ``result.npz`` file (checked: a zip of real, finite arrays, ``t`` increasing,
    ``q`` and ``p`` of shape ``(N, n)``; beside a ``meta.json``, the file that one describes);
    ``InputError`` naming the file and the reason otherwise."""
    from ..validation import check_file_size

    if value in ("straight", "march"):
        return value
    path = Path(value)
    if path.is_dir() or (path.name == "result.npz" and (path.parent / META).exists()):
        try:
            arrays, _ = read_run(path if path.is_dir() else path.parent)
        except InputError as exc:
            raise InputError(f"--guess {value!r}: {exc}") from None
    else:
        if not path.is_file():
            raise InputError(f"--guess must be straight, march or a result.npz (or run "
                             f"folder), got {value!r}: no such file")
        check_file_size(f"--guess {value!r}", path.stat().st_size)
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {key: data[key] for key in ("t", "q", "p")}
        except Exception:  # not a zip, not npy, a missing array, a pickled object
            raise InputError(f"--guess {value!r}: {path} is not a result.npz with t, q and p "
                             f"arrays") from None
    check_run_arrays(f"--guess {value!r}", arrays)
    guess = {key: np.asarray(arrays[key], dtype=float) for key in ("t", "q", "p")}
    if n is not None and guess["q"].shape[1] != n:
        raise InputError(f"--guess {value!r}: its q has shape {guess['q'].shape}, this scene "
                         f"has n = {n} coordinates")
    return guess
