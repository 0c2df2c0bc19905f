"""Every integrator the comparison runs, as the studies see it.

Each method states its traits once, beside its implementation under ``solvers/baselines/`` (a
`Integrator` constant: name, what it is, order,
symplectic, energy-conserving, knob, whether it applies to a system and why not, whether it
repeats another method there). A `Method` is that integrator as the studies see it, with
the default knob values of a sweep. Adding a method to the comparison: declare its
``Integrator`` in its implementation module, then add it to ``solvers/baselines``'
``INTEGRATORS`` (the contract is in that package's docstring).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..scenes import RunConfig
from ..solution import Status
from ..solvers import INTEGRATORS, Integrator, step_residuals


class Method(Integrator):
    """An `Integrator` of the comparison, with the default knob values of a sweep."""

    def sweep(self, config: RunConfig, halvings: int) -> list[float]:
        """Default knob values, coarse to fine: steps ``2 tau0, tau0, tau0/2, ...``
        (``halvings + 1`` values; ``tau0`` of the scene) or tolerances ``1e-3 ... 1e-12``."""
        if self.knob == "rtol":
            return [10.0 ** -k for k in range(3, 13)]
        largest = min(2 * config.tau0, (config.t_end - config.t0) / 4)
        return [largest / 2 ** j for j in range(halvings + 1)]


METHODS: dict[str, Method] = {m.name: Method(**m.traits()) for m in INTEGRATORS}


def get_methods(names) -> list[Method]:
    """Methods by name, in the order given; an unknown name is an error listing the known ones."""
    if isinstance(names, str):
        names = [s.strip() for s in names.split(",") if s.strip()]
    if not names:
        raise InputError("methods must name at least one method "
                         f"(choose from {', '.join(METHODS)})")
    chosen = []
    for name in names:
        if name not in METHODS:
            raise InputError(f"unknown method {name!r} (choose from {', '.join(METHODS)})")
        if METHODS[name] not in chosen:
            chosen.append(METHODS[name])
    return chosen


# Methods whose nodes satisfy a fixed-step map's equation (``baselines.step_equation``), and
# the map: their own residual check. The march's schemes check their equations themselves.
_STEP_EQUATIONS = {"stormer_verlet": "stormer_verlet", "leapfrog": "leapfrog", "rk4": "rk4",
                   "avf": "avf", "verlet_adaptive": "stormer_verlet"}
MARCHED = ("vddvp", "lee", "midpoint", "lee_left")


def own_residuals(system, name: str, solution, theta) -> np.ndarray | None:
    """Each step's residual of the equation method ``name`` solves, recomputed on its returned
    nodes (``|r_k|_inf``): the step map (explicit: ``z_k+1 - Phi(z_k)``; AVF: its equation;
    adaptive Verlet: Stormer-Verlet over the step taken); ``None`` for DOP853, which has no
    equation on its nodes; the march's schemes report their own (``canonical_residual``)."""
    if name in _STEP_EQUATIONS:
        z = np.hstack([solution.q, solution.p])
        return step_residuals(system, _STEP_EQUATIONS[name], solution.t, z, theta)
    if name in MARCHED:
        return solution.canonical_residual
    return None


def _check_accuracy(system, config, method, solution, tolerance, *, compiler=None,
                    cache_dir=None) -> None:
    """The accuracy check (``solvers/accuracy/judgement.py``) on the method's nodes, as for a
    march, for every method whatever its order (the reference flow holds its own error below the
    tolerance): a success judged ``inaccurate`` becomes ``INACCURATE`` (unless
    ``tolerance.stop`` is off), a ``drifted`` one ``DRIFTED`` when an accurate trajectory is
    required."""
    from ..solvers import Tolerance, assess, judge

    tolerance = tolerance or Tolerance()
    if solution.t.size < 2:
        return
    theta = system.parameter_vector(config.params)
    report, local = assess(system, solution.t, np.hstack([solution.q, solution.p]), theta,
                           tolerance, compiler=compiler, cache_dir=cache_dir,
                           exact=tolerance.exact)
    judge(solution, report, tolerance, local_error=local)


def run_method(scene, config: RunConfig, name: str, value: float, *, compiler, cache_dir=None,
               max_steps: int, time_limit: float | None = None, tol: float = 1e-10,
               tolerance=None):
    """Method ``name`` of the registry on ``scene`` at knob ``value``, then its own residual
    check: a step whose residual passes ``tol max(|z_k+1|_inf, Z)`` turns a success into
    ``RESIDUAL_TOO_LARGE``. Returns the solution, with ``canonical_residual`` the per-step
    residuals (empty where the method has no equation) and ``own_residual_max``."""
    method = get_methods([name])[0]
    reason = method.applies(scene.system)
    if reason:
        raise InputError(f"method {name!r} does not apply to scene {scene.name!r}: {reason}")
    solution = method.run(scene.system, config, value, compiler=compiler, cache_dir=cache_dir,
                          max_steps=max_steps, time_limit=time_limit)
    theta = scene.system.parameter_vector(config.params)
    _check_accuracy(scene.system, config, method, solution, tolerance, compiler=compiler,
                    cache_dir=cache_dir)
    residual = own_residuals(scene.system, name, solution, theta)
    if residual is None:
        solution.own_residual_max = None
        return solution
    solution.canonical_residual = residual
    z = np.hstack([solution.q, solution.p])
    scale = np.maximum(_start_scale(z), np.max(np.abs(z[1:]), axis=1))
    with np.errstate(invalid="ignore", divide="ignore"):  # 0 / 0 at rest: not a failure
        relative = np.nan_to_num(residual / scale[:residual.size], nan=0.0)
    worst = float(np.max(relative)) if residual.size else 0.0
    solution.own_residual_max = float(np.max(residual)) if residual.size else 0.0
    if solution.success and worst > tol:
        step = int(np.argmax(relative))
        solution.status = Status.RESIDUAL_TOO_LARGE
        solution.message = (f"{Status.RESIDUAL_TOO_LARGE.value}: step {step + 1}, residual "
                            f"{residual[step]:.3g} > {tol:g} max(|z|, Z)")
    return solution


def _start_scale(z: np.ndarray) -> float:
    """``Z``, the run's scale of a residual (no floor of 1 in the units of the state; the
    march's own test, ``solvers/marching/acceptance.py``): the start's ``|z_0|_inf`` joined
    with its first step's motion ``|z_1 - z_0|_inf``, so a start at ``z = 0`` is still judged
    against the size of its motion."""
    motion = np.abs(z[1] - z[0]) if z.shape[0] > 1 else np.zeros(0)
    values = np.concatenate([np.abs(z[0]), motion])
    return float(np.max(values[np.isfinite(values)], initial=0.0))
