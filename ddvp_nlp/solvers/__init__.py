"""Solvers: the discrete equations of ``discrete/`` turned into trajectories, and the exact flow
they are judged against. One folder per problem type (``marching/``, ``bvp/``, ``periodic/``,
``higher/``), what the whole-grid families share (``grid/``), the compared integrators
(``baselines/``), the one exact flow (``exact/``) and the verdicts measured against it
(``accuracy/``), around a small core (options, the step loop, dense output, the compiler). The
module map is in ``docs/architecture.md``.

The names below (``__all__``) are the library's public surface for the workbench (scenes, io,
runner, studies, the command line, scripts): ``tests/architecture/test_architecture.py``
holds every import of the workbench from the solvers to them. They load when first asked
for, so that importing one family does not load the others (and scipy.sparse behind them).

Every solver keeps these rules:

1. Its inputs are checked before anything is built: a bad value is an ``InputError`` that
   names the argument (or the option's field) and the value.
2. It returns a ``Solution``; a numerical failure is a status on it with a message, never an
   exception, and every accepted node is kept.
3. Success is decided by the returned points' own unscaled residuals, recomputed after the
   solve, and by the accuracy check against the exact flow; what a solver said is quoted in the
   message, never trusted.
4. Its options are objects (``options.py``) passed in the call; nothing is configured by a
   module global.
5. The equations come from ``discrete/`` and are written nowhere here.

What may import what (``tests/architecture/test_architecture.py``): the core imports no family;
``grid/`` and ``exact/`` import only the core; ``accuracy/`` the core and ``exact/``;
``marching/`` the core and ``accuracy/``; ``baselines/`` the core, ``marching/`` and
``accuracy/``; ``bvp/`` and ``periodic/`` the core, ``grid/``, ``marching/``, ``exact/`` and
``accuracy/``; ``higher/`` the core, ``grid/``, ``exact/`` and ``accuracy/``; ``chaos/`` the
core, ``marching/`` and ``exact/``. The package as a whole imports ``discrete``, ``physics`` and
the base modules, never the workbench.
"""

from typing import TYPE_CHECKING

from ..cache import lazy_exports

# name -> module (relative to this package) that defines it
PUBLIC = {
    # options
    "StepControl": "options", "Tolerance": "options", "GridOptions": "options",
    "Compilation": "options", "Output": "options", "coerce": "options",
    # initial-value problems
    "march": "marching.initial_value", "continue_march": "marching.initial_value",
    "MarchState": "marching.resume", "march_ensemble": "marching.ensemble",
    "Collect": "marching.ensemble", "end_with_parent": "marching.ensemble",
    "DDVP": "marching.scipy_method",  # the march as scipy's solve_ivp method
    "gradient": "marching.gradient",  # reverse mode of any solution's derivatives
    "DerivativeOptions": "marching.derivatives",
    # fixed ends
    "solve_bvp": "bvp.fixed_ends", "Shooting": "bvp.first_guess", "AtEnergy": "bvp.at_energy",
    "bvp_gradient": "bvp.end_gradient",  # reverse mode of a fixed-end solution's derivatives
    "transfer_derivatives": "bvp.transfer_derivatives",  # a transfer at an energy's
    "transfer_gradient": "bvp.transfer_derivatives",
    # periodic orbits
    "solve_periodic": "periodic.orbit", "check_periodic": "periodic.orbit",
    "parse_section": "periodic.orbit", "solve_periodic_family": "periodic.family",
    "follow_periodic_family": "periodic.arclength", "Continuation": "periodic.arclength",
    "Switch": "periodic.switching",
    "periodic_stability": "periodic.floquet", "Stability": "periodic.floquet",
    "linearised_orbit": "periodic.linearised",
    "find_periodic_orbits": "periodic.search", "OrbitSearch": "periodic.search",
    "orbit_gradient": "periodic.orbit_gradient",  # reverse mode of an orbit's derivatives
    # higher-order Lagrangians
    "march_higher": "higher.stepping", "solve_bvp_higher": "higher.stepping",
    # the compared integrators
    "INTEGRATORS": "baselines", "Integrator": "baselines",
    "step_residuals": "baselines.fixed_step",
    "dop853": "baselines.dop853", "flow_callable": "baselines.dop853",
    # the exact flow's reference and the verdicts (the exact flow's own pieces, exact_flow,
    # flow_with_derivatives, exact_indicators, ..., are internal: a script that measures them
    # imports them from their module and says so; tests/architecture/test_architecture.py
    # lists those scripts)
    "exact_reference": "exact.reference",
    "assess": "accuracy.judgement", "judge": "accuracy.judgement",
    "describe": "accuracy.judgement", "Level": "accuracy.judgement",
    "motion_scales": "accuracy.judgement",
    # chaos indicators on the tangent map, and their exact-flow reference
    "chaos_indicators": "chaos.indicators", "ChaosIndicators": "chaos.indicators",
    "lyapunov_spectrum": "chaos.spectrum", "Spectrum": "chaos.spectrum",
    # dense output, events, evaluation over many nodes, the compiler
    "Event": "dense", "locate": "dense", "evaluate_blocks": "grid.maps",
    "find_compiler": "compiler",
}

if TYPE_CHECKING:  # for readers and static tools; loaded on first use below
    from .accuracy.judgement import Level, assess, describe, judge, motion_scales
    from .baselines import INTEGRATORS, Integrator
    from .baselines.dop853 import dop853, flow_callable
    from .baselines.fixed_step import step_residuals
    from .bvp.at_energy import AtEnergy
    from .bvp.end_gradient import bvp_gradient
    from .bvp.first_guess import Shooting
    from .bvp.fixed_ends import solve_bvp
    from .bvp.transfer_derivatives import transfer_derivatives, transfer_gradient
    from .chaos.indicators import ChaosIndicators, chaos_indicators
    from .chaos.spectrum import Spectrum, lyapunov_spectrum
    from .compiler import find_compiler
    from .dense import Event, locate
    from .exact.reference import exact_reference
    from .grid.maps import evaluate_blocks
    from .higher.stepping import march_higher, solve_bvp_higher
    from .marching.derivatives import DerivativeOptions
    from .marching.ensemble import Collect, end_with_parent, march_ensemble
    from .marching.gradient import gradient
    from .marching.initial_value import continue_march, march
    from .marching.resume import MarchState
    from .marching.scipy_method import DDVP
    from .options import Compilation, GridOptions, Output, StepControl, Tolerance, coerce
    from .periodic.arclength import Continuation, follow_periodic_family
    from .periodic.family import solve_periodic_family
    from .periodic.floquet import Stability, periodic_stability
    from .periodic.linearised import linearised_orbit
    from .periodic.orbit import check_periodic, parse_section, solve_periodic
    from .periodic.orbit_gradient import orbit_gradient
    from .periodic.search import OrbitSearch, find_periodic_orbits
    from .periodic.switching import Switch

__getattr__, __dir__ = lazy_exports(__name__, PUBLIC)

__all__ = ["AtEnergy", "ChaosIndicators", "Collect", "Compilation", "Continuation", "DDVP",
           "DerivativeOptions", "Event",
           "GridOptions", "INTEGRATORS", "Integrator", "Level", "MarchState", "OrbitSearch",
           "Output", "Shooting",
           "Spectrum", "Stability", "StepControl", "Switch", "Tolerance", "assess", "judge",
           "bvp_gradient", "chaos_indicators", "check_periodic", "coerce", "continue_march",
           "describe", "dop853",
           "end_with_parent", "evaluate_blocks", "find_compiler", "exact_reference",
           "find_periodic_orbits", "flow_callable", "follow_periodic_family", "gradient",
           "linearised_orbit", "locate",
           "lyapunov_spectrum", "march",
           "march_ensemble", "march_higher", "motion_scales", "orbit_gradient", "parse_section",
           "periodic_stability", "solve_bvp", "solve_bvp_higher", "solve_periodic",
           "solve_periodic_family", "step_residuals", "transfer_derivatives",
           "transfer_gradient"]
