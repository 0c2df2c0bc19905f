"""Transfers at a prescribed energy: the end time an unknown, checked against DOP853 shooting
(transfer time and path) with the order fitted in N; refusals; ddvp bvp --energy."""

import numpy as np
import pytest
from helpers.common import fitted_order

from ddvp_nlp import AtEnergy, GridOptions, InputError, Tolerance, load_scene, solve_bvp
from ddvp_nlp.cli import main


def _transfers(scene_name, q_start, q_end, span, sizes, options=None):
    scene = load_scene(scene_name)
    return [solve_bvp(scene.system, q_start, q_end, span, nodes=N, options=options)
            for N in sizes]


def test_pendulum_transfer_time_and_path_converge_at_order_two_to_shooting():
    """From q = 0.5 to q = -0.036 (the scene's fixed-endpoint data) at E = 0.5, the transfer
    time is an unknown: the grid's own equations hold to round-off, every interval's energy is
    E, and the transfer time's and the path's differences from DOP853 shooting fall like
    N^-2 (fitted slopes within 0.05 of 2 over N = 51, 101, 201). The coarsest grid is 1.3%
    of the motion's size off the exact transfer (both ends fixed: ``inaccurate``, its status
    kept by ``stop=False`` to fit the order), the finer ones within 1%."""
    sizes = (51, 101, 201)
    runs = _transfers("pendulum", [0.5], [-0.036], AtEnergy(0.5, duration=9.0), sizes,
                      options=GridOptions(accuracy=Tolerance(stop=False)))
    assert [run.verdict.name for run in runs] == ["inaccurate", "accurate", "accurate"]
    times, paths = [], []
    for run in runs:
        assert run.success, run.message
        residuals = run.transfer.residuals
        assert residuals["prescribed_energy"] < 1e-13 and residuals["canonical"] < 1e-13
        exact = run.transfer.exact
        assert exact["converged"] and abs(exact["transfer_time"] - 9.62726042) < 1e-6
        times.append(abs(exact["time_difference"]))
        paths.append(exact["path_difference"])
    assert abs(fitted_order(sizes, times) + 2) < 0.05, times
    assert abs(fitted_order(sizes, paths) + 2) < 0.05, paths
    assert run.t_end == run.t[-1]  # dense output up to the found end time


@pytest.mark.slow(why="study")
def test_henon_heiles_transfer_from_the_straight_line_guess():
    """Two dimensions, no duration given (the straight line at the speed of H = E at its
    midpoint is the guess): at N = 101 and 201 the transfer matches shooting, the differences
    a factor 4 apart."""
    runs = _transfers("henon_heiles", [0.0, 0.1], [0.3, -0.1], AtEnergy(0.12), (101, 201))
    differences = []
    for run in runs:
        assert run.success, run.message
        exact = run.transfer.exact
        assert exact["converged"]
        differences.append((abs(exact["time_difference"]), exact["path_difference"]))
    ratios = np.array(differences[0]) / np.array(differences[1])
    assert np.all(np.abs(np.log2(ratios) - 2) < 0.15), ratios


def test_a_transfer_at_a_prescribed_energy_is_refused_where_it_means_nothing():
    pendulum = load_scene("pendulum").system
    with pytest.raises(InputError, match="H depends on t"):
        solve_bvp(load_scene("paper_pendulum").system, [0.5], [0.1], AtEnergy(0.5),
                  nodes=11)
    with pytest.raises(InputError, match="scheme 'fixed' has no energy equation"):
        solve_bvp(pendulum, [0.5], [0.1], AtEnergy(0.5), nodes=11, scheme="fixed")
    with pytest.raises(InputError, match="solver 'ipopt' has no free end time"):
        solve_bvp(pendulum, [0.5], [0.1], AtEnergy(0.5), nodes=11,
                  options=GridOptions(solver="ipopt"))
    with pytest.raises(InputError, match="energy must be finite, got nan"):
        AtEnergy(float("nan"))
    with pytest.raises(InputError, match="duration"):
        AtEnergy(0.5, duration=-1.0)
    with pytest.raises(InputError, match="no duration guess"):  # above the pendulum's top
        solve_bvp(pendulum, [0.5], [0.5], AtEnergy(0.5), nodes=11)


def test_bvp_energy_on_the_command_line(tmp_path, capsys):
    out = tmp_path / "transfer"
    code = main(["bvp", "pendulum", "--energy", "0.5", "--nodes", "101", "--out", str(out),
                 "--no-plot"])
    assert code == 0
    text = capsys.readouterr().out
    assert "transfer time 9.6342118" in text and "the exact flow's shooting: 9.6272604" in text
    code = main(["bvp", "spline", "--energy", "0.5", "--out", str(tmp_path / "higher")])
    assert code == 2
    assert "higher-order scene" in capsys.readouterr().err
