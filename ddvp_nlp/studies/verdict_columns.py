"""The accuracy check (``solvers/accuracy/judgement.py``) on a run of any compared method, for
the rows of the comparison, the stress grid and the sweeps.

The runs themselves go without the check, so that their run times compare like with like; it is
made here afterwards, on the nodes each method returned, with the march's default tolerances:
every method, whatever its order, against the reference flow (``solvers/exact/flow.py``), whose
own error is held below a tenth of the tolerance.
"""

from __future__ import annotations

import math

import numpy as np

from ..discrete import RULES, Scheme, interval_energies
from ..solution import Verdict
from ..solvers import Level, Tolerance, assess

COLUMNS = ("accuracy", "error_estimate")
NOT_MADE = {"accuracy": "", "error_estimate": math.nan}


def accuracy_columns(system, config, method, solution, *, compiler=None, cache_dir=None) -> dict:
    """``accuracy`` (``accurate``, ``drifted from t = T``, ``inaccurate: TEST at step K, t = T``,
    or empty where no estimate is made) and ``error_estimate`` (the largest trajectory error
    measured, relative to the motion's size)."""
    if solution.t.size < 2:
        return dict(NOT_MADE)
    theta = system.parameter_vector(config.params)
    z = np.hstack([solution.q, solution.p])
    level = None
    if method.name in RULES and method.energy_conserving:
        scheme = Scheme(method.name)
        value = float(interval_energies(system, scheme, solution.t[:2],
                                                  solution.q[:2], solution.p[:2], theta)[0])
        t0, t1 = solution.t[:2]
        level = Level(value, float(t0 + (t1 - t0) / 2 if scheme.clock == "midpoint" else t0))
    report, _ = assess(system, solution.t, z, theta, Tolerance(), level=level,
                       compiler=compiler, cache_dir=cache_dir)
    found = Verdict.of(report)
    failure = found.first_failure
    if failure is not None:
        verdict = f"inaccurate: {failure.test} at step {failure.step}, t = {failure.t:.6g}"
    elif found.drifted:
        verdict = f"drifted from t = {found.t_drift:.6g}"
    else:
        verdict = "accurate"
    return {"accuracy": verdict, "error_estimate": found.error_max}
