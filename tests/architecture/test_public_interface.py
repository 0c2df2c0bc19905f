"""The public interface: what ``import ddvp_nlp`` offers, dense output, the time keywords."""

import inspect
import pickle
import re

import numpy as np
import pytest

import ddvp_nlp
from ddvp_nlp import HamiltonianSystem, InputError, load_scene, march, solve_bvp

pytestmark = pytest.mark.smoke  # the quick tier: tests/README.md

PUBLIC = {"AtEnergy", "ChaosIndicators", "Collect", "Compilation", "Continuation", "DDVP",
          "DerivativeOptions", "Endpoints", "gradient",
          "Failure", "GridOptions", "HamiltonianSystem", "HigherOrderScene", "HigherOrderSystem",
          "InputError",
          "Lagrangian", "LagrangianSystem", "MarchState", "Output",
          "PeriodicSettings", "Scene", "Shooting",
          "Scheme", "Solution", "Spectrum", "Status", "StepControl", "Switch", "Tolerance",
          "Verdict",
          "__version__",
          "chaos_indicators", "compare", "continue_march", "lyapunov_spectrum",
          "follow_periodic_family", "linearised_orbit", "list_scenes", "load_scene", "march",
          "march_ensemble",
          "march_higher", "periodic_stability", "plot", "solve_bvp", "solve_bvp_higher",
          "solve_periodic", "solve_periodic_family", "find_periodic_orbits", "OrbitSearch"}
# No public function takes more than this many parameters: the rest are option objects. march
# has two more, the target_error a user asks for instead of tau0 (issue 40 names it so) and
# the inputs to differentiate in (derivatives, issue 47 names it so): each asks for an answer
# rather than tuning a group, so it is not an option object's field.
MOST_PARAMETERS = 12
# solve_bvp: derivatives= (issue 47); march_ensemble: t_eval and derivatives (issue 47);
# compare: its horizons, the comparison's second axis (issue 49)
MORE = {"march": 2, "solve_bvp": 1, "march_ensemble": 2, "compare": 1,
        "find_periodic_orbits": 1}


def test_public_names_are_stable_and_importable():
    assert set(ddvp_nlp.__all__) == PUBLIC
    for name in PUBLIC:
        assert getattr(ddvp_nlp, name) is not None


def _harmonic_march(tau0, scheme="vddvp", t_end=5.0):
    scene = load_scene("harmonic")
    return scene, march(scene.system, [1.0], [0.0], (0.0, t_end), tau0=tau0, scheme=scheme)


def _dense_error(scene, solution, times):
    q, p = solution.at(times)
    q_exact, p_exact = scene.exact(times, np.array([1.0]), np.array([0.0]), 0.0, 1.0)
    return np.max(np.abs(np.hstack([q - q_exact, p - p_exact])))


@pytest.mark.slow_when(lambda scheme, **_: scheme == "fixed", why="repetition")
@pytest.mark.parametrize("scheme", ["vddvp", "fixed"])
def test_dense_output_has_the_schemes_order(scheme):
    """Between the nodes (at every interval's quarter and midpoint) the interpolant's error
    against the exact motion of ``harmonic`` falls like tau^2, the order of the scheme: the fitted
    slope of log(error) against log(tau0) over four halvings is 2 within 0.15."""
    taus = np.array([0.1, 0.05, 0.025, 0.0125])
    errors = []
    for tau0 in taus:
        scene, solution = _harmonic_march(tau0, scheme)
        assert solution.success, solution.message
        t = solution.t
        between = np.concatenate([t[:-1] + 0.25 * np.diff(t), t[:-1] + 0.5 * np.diff(t)])
        errors.append(_dense_error(scene, solution, between[between <= 5.0]))
    slope = np.polyfit(np.log(taus), np.log(errors), 1)[0]
    assert abs(slope - 2.0) < 0.15, (slope, errors)


def test_dense_output_returns_the_nodes_and_the_state_at_t_end():
    """The march stops at the first node past t_end (here 5.0 for t_end = 4.98); ``at_end``
    gives the state at 4.98 with the scheme's error, the last node is a step's motion away."""
    scene, solution = _harmonic_march(0.05, t_end=4.98)
    q, p = solution.at(solution.t)
    assert np.array_equal(q, solution.q) and np.allclose(p, solution.p, rtol=0, atol=1e-15)
    assert solution.t[-1] > 4.99 and solution.t_end == 4.98
    q_end, p_end = solution.at_end()
    assert q_end.shape == (1,) and p_end.shape == (1,)
    q_exact, _ = scene.exact(np.array([4.98]), np.array([1.0]), np.array([0.0]), 0.0, 1.0)
    last_node_error = abs(solution.q[-1, 0] - q_exact[0, 0])
    assert abs(q_end[0] - q_exact[0, 0]) < 2e-3 < last_node_error


def test_dense_output_refuses_times_outside_the_run():
    _, solution = _harmonic_march(0.1)
    with pytest.raises(InputError, match="t must lie in the run's span"):
        solution.at(-0.5)


def test_dense_output_refuses_times_outside_a_short_run():
    """The span's slack is the end times' round-off in the run's own units: a run ``1e-8``
    long refuses a time ``1e-6`` of its span past its end (a slack of ``1e-12`` absolute took
    it)."""
    T = 1e-8

    def H(q, p, t):
        return (p[0] ** 2 + q[0] ** 2) / (2 * T)
    solution = march(HamiltonianSystem(H, n=1, name="fast oscillator"), [1.0], [0.0],
                     (0.0, 5 * T), tau0=0.05 * T)
    assert solution.success, solution.message
    end = solution.t[-1]  # the energy steps' last node, at or past t_end
    solution.at(end)
    with pytest.raises(InputError, match="t must lie in the run's span"):
        solution.at(end * (1 + 1e-6))


def test_a_pickled_solution_interpolates_as_the_original():
    """The dense field pickles as CasADi's serialization of the same function (documented in
    solvers/dense.py): the copy's slopes, so its answers, are the same bits; energy() works
    without the system, which is not pickled."""
    scene, solution = _harmonic_march(0.025)
    copy = pickle.loads(pickle.dumps(solution))
    assert copy.system is None and solution.system is not None
    times = np.linspace(0.0, 5.0, 301)
    assert _dense_error(scene, copy, times) < 5e-3
    assert np.array_equal(np.hstack(copy.at(times)), np.hstack(solution.at(times)))
    assert np.allclose(copy.energy(), solution.energy(), rtol=0, atol=1e-15)


def test_energy_at_the_nodes():
    _, solution = _harmonic_march(0.1)
    system = load_scene("harmonic").system
    energy = solution.energy(system)
    assert energy.shape == solution.t.shape
    assert np.allclose(energy, 0.5 * (solution.p[:, 0] ** 2 + solution.q[:, 0] ** 2))
    assert np.allclose(solution.energy(system, {"w": 2.0}),
                       0.5 * (solution.p[:, 0] ** 2 + 4 * solution.q[:, 0] ** 2))


@pytest.mark.slow(why="repetition")
def test_march_and_solve_bvp_take_t_span_as_scipy_does():
    """``t_span = (t0, t_end)`` is the fourth positional argument of both, or a keyword;
    missing or malformed, it is refused by name."""
    system = load_scene("pendulum").system
    solution = solve_bvp(system, [0.5], [0.1], (0.0, 1.0), nodes=21)
    assert solution.success and np.array_equal(
        solution.t, solve_bvp(system, [0.5], [0.1], t_span=(0.0, 1.0), nodes=21).t)
    q, _ = solution.at(0.5)
    assert q.shape == (1,) and solution.at_end()[0][0] == pytest.approx(0.1, abs=1e-12)
    marched = march(system, [0.5], [0.5], (0.0, 1.0), tau0=0.1)
    assert marched.success and marched.t[-1] >= 1.0
    for call in (lambda: solve_bvp(system, [0.5], [0.1], nodes=21),
                 lambda: march(system, [0.5], [0.5], tau0=0.1)):
        with pytest.raises(InputError, match=r"^give t_span = \(t0, t_end\)$"):
            call()
    with pytest.raises(InputError, match=r"^t_span must be a pair \(t0, t_end\), got 3\.0$"):
        solve_bvp(system, [0.5], [0.1], t_span=3.0, nodes=21)


def test_no_public_function_takes_more_than_a_dozen_parameters():
    """The groups of options are objects (``StepControl``, ``Tolerance``, ``GridOptions``,
    ``Compilation``, ``Output``), so a solve takes a handful of arguments."""
    import inspect

    counts = {name: len(inspect.signature(getattr(ddvp_nlp, name)).parameters)
              for name in PUBLIC if inspect.isfunction(getattr(ddvp_nlp, name))}
    over = {name: count for name, count in counts.items()
            if count > MOST_PARAMETERS + MORE.get(name, 0)}
    assert not over, over


@pytest.mark.slow(why="repetition")
def test_plot_writes_a_figure_for_a_march_and_for_a_bvp_solution(tmp_path):
    from PIL import Image

    from ddvp_nlp import plot
    from ddvp_nlp.io.figures import unicode_math

    scene = load_scene("pendulum")
    marched = march(scene.system, [0.5], [0.5], (0.0, 5.0), tau0=0.05)
    solved = solve_bvp(scene.system, [0.5], [-0.036], (0.0, 9.0), nodes=91)
    assert marched.success and solved.success
    for name, solution in (("march", marched), ("bvp", solved)):
        path = tmp_path / f"{name}.png"
        assert plot(solution, path, system=scene.system) == path
        with Image.open(path) as image:
            assert image.format == "PNG"
        # the suffix picks the format: vector output
        assert plot(solution, tmp_path / f"{name}.svg", system=scene.system).read_text(
        ).lstrip().startswith("<?xml")
        assert plot(solution, tmp_path / f"{name}.pdf").read_bytes()[:4] == b"%PDF"
        # without a path, the matplotlib figure; without the system, no energy panel
        with_energy = plot(solution, system=scene.system)
        without = plot(solution)
        labels = [ax.get_ylabel() for ax in without.axes]
        assert len(without.axes) == len(with_energy.axes) - 1
        # the labels' mathtext is drawn as Unicode text (io/figures.unicode_math)
        q, p, h0 = (unicode_math(label) for label in ("$q$", "$p$", "$H_0$"))
        assert q in labels and p in labels and not any(h0 in s for s in labels)


@pytest.mark.parametrize("keyword, replacement", [
    ("t_end", "t_span=(t0, t_end)"), ("t0", "t_span=(t0, t_end)"),
    ("tol", "steps=StepControl(tol=...)"), ("max_steps", "steps=StepControl(max_steps=...)"),
    ("rtol", "accuracy=Tolerance(rtol=...)"), ("accept_inaccurate",
                                               "accuracy=Tolerance(stop=False)"),
    ("compiler", "compilation=Compilation(compiler=...)"),
    ("checkpoint", "output=Output(checkpoint=...)")])
def test_a_removed_keyword_names_its_replacement(keyword, replacement):
    """march's arguments before the option objects (0.1.0) are answered with what replaced
    them, before anything is built; the signature keeps its count (the dozen above)."""
    system = load_scene("harmonic").system
    with pytest.raises(TypeError, match=re.escape(f"march() no longer takes {keyword}=: give "
                                                  f"{replacement}")):
        march(system, [1.0], [0.0], (0.0, 1.0), tau0=0.1, **{keyword: 5})
    with pytest.raises(TypeError, match="unexpected keyword argument 'nonsense'"):
        march(system, [1.0], [0.0], (0.0, 1.0), tau0=0.1, nonsense=1)
    with pytest.raises(TypeError, match=re.escape("solve_bvp() no longer takes max_iter=: give "
                                                  "options=GridOptions(max_iter=...)")):
        solve_bvp(system, [1.0], [0.0], (0.0, 1.0), nodes=5, max_iter=3)
    assert len(inspect.signature(march).parameters) == MOST_PARAMETERS + MORE["march"]
