"""t_eval and events on the march's dense output, the span error in plain numbers, named
statistics, the scene's own solve methods."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import InputError, Output, load_scene
from ddvp_nlp.solution import SolverStatistics

# each scene loaded once: a march's functions are built once per system (ddvp_nlp/cache.py)
SCENES = {name: load_scene(name) for name in ("henon_heiles", "harmonic")}


def _march(scene="henon_heiles", t_end=60.0, **output):
    return SCENES[scene].march(t_end, output=Output(**output))


@settings(max_examples=8, deadline=None)
@given(level=st.floats(-0.2, 0.2), direction=st.sampled_from([-1, 0, 1]))
def test_events_are_located_to_round_off_on_the_dense_output(level, direction):
    """At every reported time g has crossed (in the direction) and one float before it has
    not: the bracket is two adjacent numbers of the interpolant ``Solution.at``."""
    def g(t, q, p):
        return q[1] - level
    g.direction = direction
    solution = _march(events=g)
    times, states = solution.t_events[0], solution.z_events[0]
    assert times.size > 3
    assert np.array_equal(states, np.hstack(solution.at(times)))
    before = np.nextafter(times, -np.inf)
    g_at, g_before = states[:, 1] - level, solution.at(before)[0][:, 1] - level
    crossed = (g_before < 0) & (g_at >= 0) | (g_before > 0) & (g_at <= 0)
    assert crossed.all()
    if direction:
        assert np.all(direction * g_before < 0)


def test_a_terminal_event_ends_the_march_with_success():
    def g(t, q, p):
        return q[0]
    g.direction, g.terminal = 1, True
    solution = _march(events=[g], t_eval=[1.0, 2.0, 50.0])
    assert solution.status.code == "event" and solution.success
    assert solution.t[-2] < solution.t_events[0][0] <= solution.t[-1] < 60
    assert solution.t_events[0].size == 1 and list(solution.t_eval) == [1.0, 2.0]
    assert solution.statistics.steps == solution.steps


def test_bad_events_and_times_are_refused_by_name():
    with pytest.raises(InputError, match=r"events\[0\] must be a function"):
        Output(events=[3])
    bad = lambda t, q, p: q[0]  # noqa: E731
    bad.terminal = -1
    with pytest.raises(InputError, match=r"events\[0\].terminal"):
        Output(events=bad)
    with pytest.raises(InputError, match="t_eval must be sorted"):
        Output(t_eval=[2.0, 1.0, 3.0])
    # decreasing times are a backward march's (t_end < t0); a forward one refuses them
    with pytest.raises(InputError, match="t_eval must be sorted in increasing order"):
        SCENES["harmonic"].march(5.0, output=Output(t_eval=[2.0, 1.0]))
    with pytest.raises(InputError, match=r"t_eval must lie in t_span = \[0, 5\]"):
        SCENES["harmonic"].march(5.0, output=Output(t_eval=[6.0]))


def test_the_span_error_states_plain_numbers():
    solution = SCENES["harmonic"].march(2.0)
    with pytest.raises(InputError) as error:
        solution.at(-1.0)
    assert "np.float64" not in str(error.value) and "span [0, " in str(error.value)


def test_named_statistics_beside_the_dict():
    solution = SCENES["harmonic"].march(2.0)
    stats = solution.statistics
    assert isinstance(stats, SolverStatistics)
    assert stats.fast_steps + stats.careful_steps >= stats.steps == solution.steps
    assert stats.function_evaluations == (solution.newton_iterations + stats.careful_steps
                                          + stats.retries)
    with pytest.raises(AttributeError):
        stats.steps = 0
