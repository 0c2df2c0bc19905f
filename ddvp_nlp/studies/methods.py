"""The registry of every integrator the comparison runs: one line per method.

Each method states its traits once, beside its implementation under ``solvers/`` (a
:class:`~ddvp_nlp.solvers.integrator.Integrator` constant: name, what it is, order, symplectic,
energy-conserving, knob, whether it applies to a system and why not, whether it repeats another
method there). A :class:`Method` is that integrator as the studies see it, with the default knob
values of a sweep. Adding a method to the comparison: declare its ``Integrator`` in its
implementation module, then add one line to ``METHODS`` below.
"""

from __future__ import annotations

from ..errors import InputError
from ..scenes import RunConfig
from ..solvers import avf, baselines, lee_left, paper_schemes, scipy_dop853, verlet_adaptive
from ..solvers.integrator import Integrator
from ..solvers.scipy_dop853 import dop853  # noqa: F401 (the reference solution of the studies)


class Method(Integrator):
    """An :class:`Integrator` of the comparison, with the default knob values of a sweep."""

    def sweep(self, config: RunConfig, halvings: int) -> list[float]:
        """Default knob values, coarse to fine: steps ``2 tau0, tau0, tau0/2, ...``
        (``halvings + 1`` values; ``tau0`` of the scene) or tolerances ``1e-3 ... 1e-12``."""
        if self.knob == "rtol":
            return [10.0 ** -k for k in range(3, 13)]
        largest = min(2 * config.tau0, (config.t_end - config.t0) / 4)
        return [largest / 2 ** j for j in range(halvings + 1)]


METHODS: dict[str, Method] = {m.name: Method(**m.traits()) for m in (
    paper_schemes.VDDVP,
    paper_schemes.LEE,
    paper_schemes.MIDPOINT,
    baselines.STORMER_VERLET,
    baselines.LEAPFROG,
    verlet_adaptive.VERLET_ADAPTIVE,
    avf.AVF,
    baselines.RK4,
    scipy_dop853.DOP853,
    lee_left.LEE_LEFT,
)}


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
