"""The accuracy check (``solvers/accuracy.py``) on a run of any compared method, for the rows of
the comparison, the stress grid and the sweeps.

The runs themselves go without the check, so that their run times compare like with like; it is
made here afterwards, on the nodes each method returned, with the march's default tolerances.
The reference step is one RK4 step for methods of order 2 or less and two half steps for orders
3 and 4; above that (DOP853) the reference is less accurate than the method and no estimate is
made.
"""

from __future__ import annotations

import math

import numpy as np

from ..discrete import equations
from ..discrete.scheme import RULES, Scheme
from ..solvers.accuracy import Tolerance, assess

COLUMNS = ("accuracy", "error_estimate")
NOT_MADE = {"accuracy": "", "error_estimate": math.nan}


def accuracy_columns(system, config, method, solution, *, compiler=None, cache_dir=None) -> dict:
    """``accuracy`` (``accurate``, or ``inaccurate: TEST at step K, t = T``, or empty where no
    estimate is made) and ``error_estimate`` (the propagated global error at the end)."""
    if method.order > 4 or solution.t.size < 2:
        return dict(NOT_MADE)
    theta = system.parameter_vector(config.params)
    z = np.hstack([solution.q, solution.p])
    level = None
    if method.name in RULES and method.energy_conserving:
        level = float(equations.interval_energies(system, Scheme(method.name), solution.t[:2],
                                                  solution.q[:2], solution.p[:2], theta)[0])
    report, _ = assess(system, solution.t, z, theta, Tolerance(), level=level,
                       substeps=1 if method.order <= 2 else 2, compiler=compiler,
                       cache_dir=cache_dir)
    failure = report["first_failure"]
    verdict = ("accurate" if failure is None else
               f"inaccurate: {failure['test']} at step {failure['step']}, t = {failure['t']:.6g}")
    return {"accuracy": verdict, "error_estimate": report["global_error_estimate"]}
