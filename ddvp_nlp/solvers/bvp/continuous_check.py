"""The accuracy check of a fixed-end grid against the continuous problem's solution: the
solution near the grid's found by multiple shooting from the grid's own start
(``exact/shooting.py``, segments chosen by the flow's error control, read at the nodes), each
interval against the exact flow, the energy level of the first interval where one is given,
the nodal drift (``accuracy/judgement.py``). Shared by the unconstrained fixed ends
(`fixed_ends`) and the constrained ones (`constrained_ends`), whose exact flow is
index-reduced and projected."""

from __future__ import annotations

import numpy as np

from ..accuracy.judgement import Judgement, Level, fixed_ends_report, motion_scales
from ..compiler import find_compiler
from ..exact.shooting import shoot
from ..grid.problem import GridRequest


def judged_against_shooting(request: GridRequest, t, q, p, *, level: Level | None = None,
                            flow: str = "exact flow") -> tuple[dict, np.ndarray]:
    """``(report, local)`` of the grid ``t, q, p``: with no continuous solution near, the
    verdict is ``inaccurate`` with that reason (a verified discrete solution can exist where
    no motion does: its end error, small beside a huge motion, says nothing then). ``flow``
    names the exact flow in the report's estimate."""
    system, tolerance = request.system, request.options.accuracy
    compiler = find_compiler(request.compilation.compiler)
    check = Judgement(system, request.theta, tolerance, compiler=compiler,
                      cache_dir=request.compilation.cache_dir)
    z = np.hstack([q, p])
    shot = shoot(system, request.theta, t, z, q[-1], motion_scales(
        z.min(axis=0), z.max(axis=0), np.abs(z).max(axis=0), system.n), compiler=compiler,
        cache_dir=request.compilation.cache_dir)
    if shot.trajectory is None:
        report, local = check.report(t, z, level=level)
        if report["verdict"] == "inaccurate":
            return report, local
        report["verdict"] = "inaccurate"
        report["first_failure"] = {"step": t.size - 2, "t": float(t[-2]),
                                   "test": "continuous solution", "value": None,
                                   "limit": tolerance.global_tol, "detail": shot.reason}
        return report, local
    report, local = check.report(t, z, level=level, exact=shot.states)
    report = fixed_ends_report(report, t)  # both ends fixed: off the solution, not drifted
    solution = "continuous constrained solution" if flow != "exact flow" else \
        "continuous solution"
    report["estimate"] = (f"the {solution} near this one (multiple shooting with the {flow} on "
                          f"{shot.cuts.size - 1} segments: p_0 = {shot.p0.tolist()})")
    return report, local


__all__ = ["judged_against_shooting"]
