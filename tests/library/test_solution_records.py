"""What a solve found is a typed record on `Solution`; `written_stats` lays it out under the
keys and in the order run files have always had (``meta.json``'s ``solver`` block is written
from it, byte for byte)."""

import numpy as np

from ddvp_nlp.solution import EndsRecord, MarchRecord, Solution, Status, TransferRecord
from ddvp_nlp.solvers.grid.policy import Stage


def _solution(**records) -> Solution:
    t = np.linspace(0.0, 1.0, 3)
    return Solution(t=t, q=np.zeros((3, 1)), p=np.zeros((3, 1)), status=Status.SUCCESS,
                    message="", scheme="vddvp", energy_residual=np.zeros(1),
                    canonical_residual=np.zeros(2), **records)


def test_a_fixed_endpoint_record_is_written_where_its_keys_always_stood():
    stage = Stage("vddvp equations", "newton", True, "converged", 3, 0.5)
    stats = {"solver": "newton", "return_status": "converged", "iterations": 3,
             "iterations_total": 3, "energy_scale": 0.1, "tau_floor": 1e-4}
    ends = EndsRecord(stages=(stage,), action=1.5, p_sign_changes=(2,), canonical_limit=1e-10,
                      energy_limit=1e-11, canonical_residual_max=1e-15,
                      energy_residual_max=1e-16, tau_min=0.01)
    written = _solution(stats=stats, ends=ends).written_stats()
    assert list(written) == ["solver", "phases", "return_status", "iterations",
                             "iterations_total", "action", "energy_scale", "tau_floor",
                             "p_sign_changes", "canonical_limit", "energy_limit",
                             "canonical_residual_max", "energy_residual_max", "tau_min"]
    assert written["phases"] == [stage.record()] and written["p_sign_changes"] == [2]
    # a point that is not finite has no residual maxima (as before: the keys are absent)
    bare = EndsRecord(stages=(), action=np.nan, p_sign_changes=(0,), canonical_limit=1.0,
                      energy_limit=1.0)
    assert "tau_min" not in _solution(stats=stats, ends=bare).written_stats()


def test_a_transfer_record_is_written_around_the_newtons_record():
    transfer = TransferRecord(transfer_time=9.6, energy=0.5, residuals={"canonical": 1e-15},
                              residual_limit=1e-10, tau_min=0.04, tau_max=0.05)
    written = _solution(stats={"transfer": {"iterations": 4}}, transfer=transfer).written_stats()
    assert list(written) == ["transfer_time", "energy", "residuals", "limit", "transfer",
                             "tau_min", "tau_max"]
    later = TransferRecord(**{**vars(transfer), "exact": {"converged": True},
                              "fixed_time_start": {"durations": [9.0]}})
    assert list(_solution(stats={"transfer": {}}, transfer=later).written_stats())[-2:] == [
        "exact", "fixed_time_start"]


def test_a_march_record_adds_only_the_keys_its_run_set():
    march = MarchRecord(theta=[1.0])
    written = _solution(stats={"retries": 0}, march=march).written_stats()
    assert written == {"retries": 0, "theta": [1.0], "solvability_warning": None,
                       "least_squares": []}
    march.carried, march.backward = {"tau": 0.1}, True
    assert _solution(stats={}, march=march).written_stats()["carried"] == {"tau": 0.1}
    assert _solution(stats={}, march=march).written_stats()["backward"] is True
    assert _solution(stats={"retries": 2}).written_stats() == {"retries": 2}


def test_energy_reads_the_parameters_the_march_used():
    class Linear:
        def parameter_vector(self, params=None):
            return np.array([1.0])

        def energy(self, q, p, t, theta):
            return theta[0] * np.ones(t.size)

    solution = _solution(march=MarchRecord(theta=[2.0]))
    assert np.all(solution.energy(Linear()) == 2.0)
    assert np.all(_solution().energy(Linear()) == 1.0)
