"""ddvp_nlp: the difference discrete variational principle with variable time steps, on CasADi.

Node times are unknowns; varying them gives a discrete energy equation, so the schemes are
symplectic and conserve energy. See docs/theory.md for the equations in this code's notation and
docs/guide.md for a user guide.

The public interface is ``__all__``: solvers (``march``, ``march_ensemble``, ``solve_bvp``,
``solve_periodic``, ``solve_periodic_family``, ``follow_periodic_family``, ``march_higher``,
``solve_bvp_higher``, ``find_periodic_orbits``: orbits at an energy from a section alone), the
march as a method of scipy's ``solve_ivp`` (``DDVP``), the
stability of a periodic orbit (``periodic_stability``), chaos indicators on the march's
tangent map (``chaos_indicators``, ``lyapunov_spectrum``), their options (``StepControl``,
``Tolerance``, ``GridOptions``, ``Compilation``, ``Output``, ``Continuation``, ``Switch``
(branch switching at a branch point of a followed family), ``AtEnergy``
for a transfer at a prescribed energy), their result (``Solution``, ``Status``) and its
figure (``plot``), systems and schemes, scenes, and the work-precision comparison of
integrators (``compare``).
Everything else is reached through its module and may change.
"""

from typing import TYPE_CHECKING

from . import startup  # noqa: F401 - first: holds Ctrl-C while the command starts
from .cache import lazy_exports
from .discrete import Scheme
from .errors import InputError
from .physics import HamiltonianSystem, HigherOrderSystem, Lagrangian, LagrangianSystem
from .scenes import (
    Endpoints,
    HigherOrderScene,
    PeriodicSettings,
    Scene,
    list_scenes,
    load_scene,
)
from .solution import Failure, Solution, Status, Verdict
from .solvers import Compilation, GridOptions, Output, StepControl, Tolerance

if TYPE_CHECKING:  # for readers and static tools (the API pages); loaded on first use below
    from .solvers import (
        DDVP,
        AtEnergy,
        ChaosIndicators,
        Collect,
        Continuation,
        DerivativeOptions,
        MarchState,
        OrbitSearch,
        Shooting,
        Spectrum,
        Switch,
        chaos_indicators,
        continue_march,
        find_periodic_orbits,
        follow_periodic_family,
        gradient,
        linearised_orbit,
        lyapunov_spectrum,
        march,
        march_ensemble,
        march_higher,
        periodic_stability,
        solve_bvp,
        solve_bvp_higher,
        solve_periodic,
        solve_periodic_family,
    )

# The solvers are loaded when first asked for (PEP 562): `from ddvp_nlp import march` loads the
# march and not the fixed-endpoint, periodic and higher-order families with scipy.sparse and
# scipy.linalg behind them (import ddvp_nlp took 0.43 s CPU with every family, 75% of a warm
# `ddvp march`; measured).
_solver, _names = lazy_exports(__name__, {name: "solvers" for name in (
    "march", "march_ensemble", "Collect", "MarchState", "continue_march", "solve_bvp",
    "Shooting", "AtEnergy", "solve_periodic", "solve_periodic_family", "periodic_stability",
    "follow_periodic_family", "Continuation", "Switch", "find_periodic_orbits", "OrbitSearch",
    "linearised_orbit", "march_higher", "solve_bvp_higher",
    "chaos_indicators", "lyapunov_spectrum", "ChaosIndicators", "Spectrum", "DDVP",
    "gradient", "DerivativeOptions")})


# The version, written here and in pyproject.toml (tests/docs/test_links.py: they and CHANGELOG.md's
# newest release agree). A literal, not importlib.metadata: that lookup (and the email package
# behind it) was a third of what `import ddvp_nlp` adds to numpy and casadi, and it answered the
# installed copy's version, not this tree's.
__version__ = "0.2.0"


def __getattr__(name: str):
    return _solver(name)


def __dir__() -> list[str]:
    return sorted({*_names(), "__version__"})


def plot(solution: Solution, path=None, *, system=None, params=None, title: str | None = None):
    """Draw ``solution`` as ``ddvp march`` draws a run: ``q``, ``p``, the step length where it
    varies, the phase portrait (and the configuration plane for two or more degrees of
    freedom), and with the ``system`` that was solved the relative energy drift
    ``|H - H0| / |H0|``.

    Args:
        solution: a result of ``march``, ``solve_bvp``, ``march_higher`` or ``solve_bvp_higher``.
        path: where to write the figure (PNG, SVG or PDF by the suffix); ``None`` returns the
            ``matplotlib.figure.Figure`` instead.
        system: the solved system, for the energy panel (omitted without it).
        params: its parameter values (default: those of the solve).
        title: the figure's title (default: scheme, steps and status).

    Returns:
        ``path``, or the ``matplotlib.figure.Figure`` when ``path`` is ``None``.
    """
    # The one import from the root into io/ (docs/architecture.md): a facade, imported here
    # and not at the top so that `import ddvp_nlp` loads no figure code.
    from .io.run_figure import plot_solution

    return plot_solution(solution, path, system=system, params=params, title=title)


def compare(problem, methods=None, *, q0=None, p0=None, t_span=None, params=None,
            target_errors=None, options=None, compilation=None, workers=None, out=None,
            progress: bool = False, horizons=None):
    """Compare integrators on one problem, as ``ddvp compare`` does (the command calls this):
    each method over a sweep of its accuracy knob, every run timed and measured against the
    exact motion.

    Args:
        problem: a scene name (``"kepler"``) or file, a `Scene`, or a `HamiltonianSystem`
            (then ``q0``, ``p0`` and ``t_span`` are needed, and the sweeps start from a step
            derived from the motion's time scale).
        methods: method names (``["vddvp", "rk4", "dop853"]`` or ``"vddvp,rk4"``); default every
            method that applies and does not repeat another. An unknown name is refused with
            the list of known ones.
        q0: the start's positions (for a scene, they replace its own).
        p0: the start's momenta (for a scene, they replace its own).
        t_span: the span ``(t0, t_end)`` (for a scene, it replaces its own).
        params: parameter values (for a scene, they replace its own; they may also set
            ``tau0``).
        target_errors: trajectory errors (relative to the motion's size) at which the
            methods that can aim at an error (the march's schemes) run, one
            ``march(..., target_error=E)`` each, instead of their step sweep.
        options: the sweeps, timing and reference (``studies.CompareOptions``: ``halvings``,
            ``repeats``, ``knobs``, ``reference``, ...).
        compilation: for the compiled methods, as in `march`.
        workers: where the runs go (``runner.Workers``; default one after the other here).
        out: a folder to write ``work_precision.csv``, ``.png`` and ``summary.md`` to (with
            ``horizons``: a report per horizon, ``horizons.md`` and the figures).
        progress: a progress bar on stderr.
        horizons: horizons ``T`` in the problem's time units (a list or ``"1e2,1e3,1e4"``): the
            comparison is made to each ``t_end = t0 + T``, the sweeps cut to what each
            affords (``ddvp compare --horizons``' machinery).

    Returns:
        A ``WorkPrecision``: ``rows`` (one dict per run, failed runs kept with ``status`` and
        ``message``), ``failed``, ``best(error)``, ``to_csv(path)``, ``plot(path=None)``.
        With ``horizons``, a ``HorizonComparison``: ``results`` (horizon to
        ``WorkPrecision``), ``best(error, horizon)`` (the cheapest method, its rule and why,
        or ``None`` and why), ``crossovers()``, ``plot_crossover(path=None)``, ``plot``,
        ``to_csv``.
    """
    # The second facade (docs/architecture.md): the comparison is a study of the workbench,
    # imported here and not at the top so that `import ddvp_nlp` loads none of it.
    from .studies.comparison import compare as run_comparison

    return run_comparison(problem, methods, q0=q0, p0=p0, t_span=t_span, params=params,
                          target_errors=target_errors, options=options,
                          compilation=compilation, workers=workers, out=out, progress=progress,
                          horizons=horizons)


__all__ = ["AtEnergy", "ChaosIndicators", "Collect", "Compilation", "Continuation", "DDVP",
           "DerivativeOptions", "Endpoints",
           "Failure", "GridOptions", "HamiltonianSystem", "HigherOrderScene", "HigherOrderSystem",
           "InputError", "Lagrangian", "LagrangianSystem", "MarchState", "OrbitSearch",
           "Output", "PeriodicSettings", "Scene", "Scheme", "Shooting", "Solution", "Spectrum",
           "Status", "StepControl", "Switch", "Tolerance", "Verdict", "__version__",
           "chaos_indicators",
           "compare", "continue_march", "find_periodic_orbits", "follow_periodic_family",
           "gradient", "linearised_orbit", "list_scenes", "load_scene", "lyapunov_spectrum",
           "march", "march_ensemble", "march_higher", "periodic_stability", "plot", "solve_bvp",
           "solve_bvp_higher", "solve_periodic", "solve_periodic_family"]
