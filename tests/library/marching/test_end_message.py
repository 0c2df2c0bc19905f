"""The success message names the end time it reached to the digits a user typed: a span ending at
1000000100 read 'reached t_end = 1e+09' (found by a user marching at a large time offset)."""

from __future__ import annotations

from ddvp_nlp import load_scene, march


def test_the_end_time_is_printed_to_its_digits():
    config = load_scene("pendulum").resolve({})
    system = load_scene("pendulum").system
    solution = march(system, config.q0, config.p0, (1e9, 1e9 + 100.0), tau0=0.1,
                     accuracy=None)
    assert solution.success
    assert "reached t_end = 1000000100 in" in solution.message
