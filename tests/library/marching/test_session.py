"""The march session (``solvers/marching/session.py``): its monitors are the ones the options
ask for, in the order they watch, and a new monitor plugs in through ``kinds`` without editing
the session, seeing every node once and adding to the solution at the end."""

import numpy as np

from ddvp_nlp import Compilation, Output, StepControl, Tolerance, load_scene
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.marching import (
    MONITORS,
    MarchMonitor,
    MarchSession,
    MarchState,
    check_problem,
    march,
)
from ddvp_nlp.solvers.marching.session import build_parts, make_monitors

CAREFUL = Compilation(fast=False)


def _problem(scheme="vddvp", t_end=2.0, steps=None):
    scene = load_scene("pendulum")
    return check_problem(scene.system, Scheme.coerce(scheme), [1.0], [0.0], None, (0.0, t_end),
                         0.05, steps or StepControl(), None)


class StepCounter(MarchMonitor):
    """A monitor made for this test: counts the nodes it watched; never ends the run."""

    @classmethod
    def from_options(cls, session):
        return cls()

    def __init__(self):
        self.steps = 0

    def watch(self, nodes, first, advance):
        self.steps += advance.count
        return None

    def finish(self, solution, outcome):
        solution.stats["counted_steps"] = self.steps


def test_a_new_monitor_plugs_in_through_kinds_and_changes_nothing_else():
    problem = _problem()
    plain = MarchSession(problem, Tolerance(), CAREFUL, Output()).run()
    counted = MarchSession(problem, Tolerance(), CAREFUL, Output(),
                           kinds=(*MONITORS, StepCounter)).run()
    assert counted.success, counted.message
    assert counted.stats["counted_steps"] == counted.t.size - 1
    for name in ("t", "q", "p", "energy_residual", "canonical_residual", "solvability"):
        assert np.array_equal(getattr(counted, name), getattr(plain, name)), name
    assert (counted.status, counted.message, counted.verdict) == \
        (plain.status, plain.message, plain.verdict)
    # march() is the same session with the listed kinds
    marched = march(problem.system, [1.0], [0.0], (0.0, 2.0), tau0=0.05, compilation=CAREFUL)
    assert np.array_equal(marched.t, plain.t) and marched.message == plain.message


def test_a_continued_session_has_its_monitor_watch_the_earlier_nodes_again():
    problem = _problem()
    first = MarchSession(_problem(t_end=1.0), None, CAREFUL, Output()).run()
    state = MarchState.of(first.t, first.q, first.p, 1.0, first.march.carried)
    continued = MarchSession(problem, None, CAREFUL, Output(), start=state,
                             kinds=(*MONITORS, StepCounter)).run()
    assert continued.t[first.t.size - 1] == first.t[-1]
    assert continued.stats["counted_steps"] == continued.t.size - 1


def _made(problem, accuracy, output):
    session = MarchSession(problem, accuracy, CAREFUL, output)
    session.parts = build_parts(problem, CAREFUL, None)
    return [type(monitor).__name__ for monitor in make_monitors(MONITORS, session)]


def test_the_monitors_are_the_ones_the_options_ask_for_in_the_order_they_watch():
    # a fixed-step march without a check watches only what its loop carries
    assert _made(_problem("fixed"), None, Output()) == ["CarryTracker"]
    assert _made(_problem(), Tolerance(), Output()) == \
        ["SolvabilityMonitor", "EarlyVerdict", "CarryTracker"]
    assert _made(_problem(), Tolerance(stop=False), Output()) == \
        ["SolvabilityMonitor", "CarryTracker"]
    output = Output(events=lambda t, q, p: q[0], stop=lambda: False,
                    checkpoint=lambda t, z: None)
    assert _made(_problem(steps=StepControl(energy_guard=1e-3)), Tolerance(), output) == \
        ["EnergyGuard", "SolvabilityMonitor", "EarlyVerdict", "Events", "StopRequest",
         "CarryTracker", "Checkpoint"]
