"""Output times beyond the machine's memory are refused by name before anything is built
(issue 45: ``Output(t_eval=np.linspace(0, 5, 10**8))`` ended in a ``MemoryError`` after 22-47 s
naming no argument; the command line refused it up front)."""

import numpy as np
import pytest

from ddvp_nlp import InputError, Output, load_scene, march, validation


@pytest.mark.parametrize("n_times, refused", [(10 ** 4, True), (10, False)])
def test_output_times_beyond_memory_are_refused_by_name(monkeypatch, n_times, refused):
    monkeypatch.setattr(validation, "available_memory", lambda: 10 ** 6)  # a 1 MB machine
    scene = load_scene("harmonic")
    output = Output(t_eval=np.linspace(0.0, 5.0, n_times))
    if refused:
        with pytest.raises(InputError, match=r"len\(t_eval\) = 10000 .*more than this machine"):
            march(scene.system, [1.0], [0.0], (0.0, 5.0), tau0=0.1, output=output,
                  accuracy=None)
    else:
        run = march(scene.system, [1.0], [0.0], (0.0, 5.0), tau0=0.1, output=output,
                    accuracy=None)
        assert run.z_eval.shape == (n_times, 2)


@pytest.mark.parametrize("times", [[0.0, 1.0, 0.5], [3.0, 2.0, 2.5]])
def test_unsorted_output_times_are_still_refused(times):
    scene = load_scene("harmonic")
    with pytest.raises(InputError, match="t_eval must be sorted"):
        march(scene.system, [1.0], [0.0], (0.0, 5.0), tau0=0.1, output=Output(t_eval=times))
