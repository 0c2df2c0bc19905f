"""``compare``: the work-precision comparison from Python, the one ``ddvp compare`` runs.

It takes a scene name or file, a `Scene`, or a `HamiltonianSystem` with its start and span,
checks everything (the problem, the methods, the knobs, the target errors, the horizons) before
any solver is built, runs the plan of ``studies/work_precision.py`` and returns its
`WorkPrecision`: the rows, failed runs with their reasons, ``plot``, ``to_csv``, ``best``. With
``out`` it also writes ``work_precision.csv``, ``.png`` and ``summary.md`` there, as the command
does. With ``horizons`` it compares at each horizon (``studies/horizons_report.py``, the
machinery of ``ddvp compare --horizons``) and returns a `HorizonComparison`, whose
``best(error, horizon)`` and ``crossovers()`` say which method is cheapest where.

A system has no first step of its own: its sweeps start from a step derived from the motion
(`motion_time`: the time the fastest coordinate of the exact flow takes to cross its range at
its greatest speed, over `STEPS_PER_CROSSING`), so the knob ranges follow the orbit's scale.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping

import numpy as np

from ..errors import InputError
from ..physics import HamiltonianSystem, LagrangianSystem
from ..runner.tasks import Workers
from ..scenes import HigherOrderScene, Scene, load_scene
from ..solvers import Compilation, exact_reference
from ..validation import check_real
from .comparable import check_comparable
from .horizons import parse_horizons
from .horizons_choice import HorizonComparison
from .horizons_report import horizons_study
from .methods import get_methods
from .work_precision import CompareOptions, WorkPrecision, plan_work_precision, run_work_precision
from .work_precision_report import write_work_precision

# A system's sweep starts from a step this many times shorter than the motion's crossing time
# (harmonic: the crossing time 2/omega is T/pi, so the first step is about T/50 and the
# sweep's largest, 2 tau0, T/25).
STEPS_PER_CROSSING = 16
# The exact flow that measures the crossing time: its tolerance and the samples per step.
TIME_SCALE_RTOL = 1e-8
SAMPLES_PER_STEP = 8


def compare(problem, methods=None, *, q0=None, p0=None, t_span=None,
            params: Mapping[str, object] | None = None, target_errors=None,
            options: CompareOptions | None = None, compilation: Compilation | None = None,
            workers: Workers | None = None, out: str | os.PathLike | None = None,
            progress: bool = False, interruptible=None, horizons=None,
            time_unit: float = 1.0) -> WorkPrecision | HorizonComparison:
    """The comparison of ``ddvp_nlp.compare`` (its docstring has the arguments);
    ``interruptible`` is the command's (a figure an interrupt may skip). With ``horizons``
    the comparison at each (`horizons_study`), a `HorizonComparison`."""
    options = _options(options, methods, target_errors)
    if options.methods is not None:  # names checked before the system's flow is built
        get_methods(options.methods)
    if horizons is not None:
        horizons = parse_horizons(horizons)
        check_real("time_unit", time_unit, positive=True)
    scene, overrides = _scene_of(problem, q0, p0, t_span, params)
    if scene.system.n_constraints:
        _constrained_comparable(scene, overrides, options)
    if horizons is not None:
        return horizons_study(scene, horizons, out=out, unit=time_unit, overrides=overrides,
                              options=options, compilation=compilation, workers=workers,
                              progress=progress)
    plan = plan_work_precision(scene, overrides=overrides, options=options,
                               compilation=compilation, workers=workers)
    if out is not None:
        return write_work_precision(plan, out, progress=progress, interruptible=interruptible)
    with tempfile.TemporaryDirectory(prefix="ddvp-compare-") as scratch:
        return run_work_precision(plan, os.path.join(scratch, "work_precision.csv"),
                                  progress=progress)


def _constrained_comparable(scene, overrides, options) -> None:
    """What a comparison of a constrained scene cannot do yet, refused by name: target errors
    (the constrained march does not aim at an error) and a backward span (it marches
    forwards only)."""
    m = scene.system.n_constraints
    what = f"scene {scene.name!r} has {m} constraint{'s' if m > 1 else ''}"
    if options.target_errors is not None:
        raise InputError(f"{what}; compare does not take target_errors on a constrained "
                         f"scene yet (its march does not aim at an error): give knobs or "
                         f"let the sweeps run")
    config = scene.resolve(overrides)
    if config.t_end < config.t0:
        raise InputError(f"{what}; compare does not take a backward span on a constrained "
                         f"scene yet (t_end = {config.t_end!r} < t0 = {config.t0!r})")


def _options(options, methods, target_errors) -> CompareOptions:
    if options is not None and not isinstance(options, CompareOptions):
        raise InputError(f"options must be CompareOptions(...), got {type(options).__name__}")
    options = options or CompareOptions()
    changes = {}
    if methods is not None:
        if options.methods is not None:
            raise InputError("give methods once: as the argument or in options, not both")
        changes["methods"] = methods
    if target_errors is not None:
        if options.target_errors is not None:
            raise InputError("give target_errors once: as the argument or in options")
        changes["target_errors"] = target_errors
    return CompareOptions(**{**options.__dict__, **changes}) if changes else options


def _scene_of(problem, q0, p0, t_span, params) -> tuple[Scene, dict]:
    """The scene to compare and its overrides: a scene's settings replaced by the given
    start, span and parameters; a system made a scene with them."""
    overrides = dict(params or {})
    if isinstance(problem, (str, os.PathLike)):
        problem = load_scene(os.fspath(problem))
    if isinstance(problem, HigherOrderScene):
        check_comparable(problem)  # says why: the compared methods need H
    if isinstance(problem, HamiltonianSystem):
        return _system_scene(problem, q0, p0, t_span, overrides), overrides
    if not isinstance(problem, Scene):
        raise InputError("problem must be a scene name or file, a Scene or a "
                         f"HamiltonianSystem, got {type(problem).__name__}")
    for name, value in (("q0", q0), ("p0", p0)):
        if value is not None:
            overrides[name] = value
    if t_span is not None:
        overrides["t0"], overrides["t_end"] = _span(t_span)
    problem.resolve(overrides)  # every name and value checked here
    return problem, overrides


def _span(t_span) -> tuple[float, float]:
    try:
        t0, t_end = (float(x) for x in t_span)
    except (TypeError, ValueError):
        raise InputError(f"t_span must be a pair (t0, t_end), got {t_span!r}") from None
    return t0, t_end


def _system_scene(system, q0, p0, t_span, overrides) -> Scene:
    if isinstance(system, LagrangianSystem):
        raise InputError("compare takes a HamiltonianSystem; for L(q, v, t) give "
                         "Scene(Lagrangian(L), ...)")
    missing = [name for name, value in (("q0", q0), ("p0", p0), ("t_span", t_span))
               if value is None]
    if missing:
        raise InputError(f"a HamiltonianSystem is compared from a start over a span: give "
                         f"{', '.join(missing)}")
    t0, t_end = _span(t_span)
    span = t_end - t0
    draft = Scene(system.hamiltonian, n=system.n, params=dict(system.params), q0=q0, p0=p0,
                  t0=t0, t_end=t_end, tau0=span / 4, name=system.name)
    draft.__dict__["system"] = system  # the same built functions, kept with the system
    config = draft.resolve(overrides)
    tau0 = min(span / 4, motion_time(system, config) / STEPS_PER_CROSSING)
    scene = Scene(system.hamiltonian, n=system.n, params=dict(system.params), q0=q0, p0=p0,
                  t0=t0, t_end=t_end, tau0=tau0, name=system.name,
                  description=f"{system.name}, its first step {tau0:.3g} from the motion's "
                              f"time scale")
    scene.__dict__["system"] = system
    return scene


def motion_time(system, config) -> float:
    """The time the fastest coordinate of the motion takes to cross its range at its
    greatest speed, ``min_i range(z_i) / max |dz_i/dt|``, on the exact flow from the run's
    start over its span (dense output, `SAMPLES_PER_STEP` samples per step)."""
    theta = system.parameter_vector(config.params)
    z0 = np.concatenate([config.q0, config.p0])
    reference = exact_reference(system, z0, config.t0, config.t_end, theta,
                                rtol=TIME_SCALE_RTOL)
    nodes = reference.fine.nodes()[0]
    fractions = np.arange(SAMPLES_PER_STEP) / SAMPLES_PER_STEP
    t = np.append((nodes[:-1, None] + np.diff(nodes)[:, None] * fractions).ravel(), nodes[-1])
    z = reference.fine.z(t)
    speed = np.max(np.abs(np.diff(z, axis=0)) / np.diff(t)[:, None], axis=0)
    extent = np.ptp(z, axis=0)
    moving = (speed > 0) & (extent > 0)
    if not moving.any():
        raise InputError("the start is an equilibrium: nothing moves, there is nothing to "
                         "compare")
    return float(np.min(extent[moving] / speed[moving]))


__all__ = ["STEPS_PER_CROSSING", "compare", "motion_time"]
