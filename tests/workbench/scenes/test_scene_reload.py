"""A scene file loaded again in one process is not run again: the scene returned is a copy with
its own parameters and start, sharing the functions, and so the system and what was built for
it (a second `load_scene('kepler').march()` had rebuilt every function: 0.47 s of CPU against
0.12 s shared). A changed file is run anew. Counted in builds and objects, not seconds."""

from __future__ import annotations

import numpy as np

from ddvp_nlp import load_scene

SCENE = ("from ddvp_nlp import Scene\n"
         "RUNS = []\n"
         "def hamiltonian(q, p, t, k):\n    return p[0]**2 / 2 + k * q[0]**2 / 2\n"
         "scene = Scene(hamiltonian, n=1, q0=[1.0], p0=[0.0], tau0=0.05, t_end=1,\n"
         "              params={{'k': {k}}})\n")


def test_a_scene_loaded_again_is_its_own_copy_sharing_the_system(tmp_path):
    first, again = load_scene("kepler"), load_scene("kepler")
    assert again is not first and again.system is first.system
    again.params["e"] = 0.3
    again.tau0 = 0.1
    fresh = load_scene("kepler")
    assert fresh.params == first.params == {"e": 0.5} and fresh.tau0 == first.tau0 != 0.1
    path = tmp_path / "osc.py"
    path.write_text(SCENE.format(k=1.0))
    load_scene(str(path)).q0[0] = 5.0  # its start, changed in place
    assert load_scene(str(path)).q0 == [1.0]


def test_a_scene_changed_before_its_system_gets_its_own_system():
    changed = load_scene("kepler")
    changed.params = {"e": 0.3}
    assert changed.system is not load_scene("kepler").system
    assert changed.system.parameter_vector({}) == [0.3]


def test_a_changed_file_runs_again(tmp_path):
    path = tmp_path / "osc.py"
    path.write_text(SCENE.format(k=1.0))
    first = load_scene(str(path))
    assert load_scene(str(path)).system is first.system
    path.write_text(SCENE.format(k=4.0))
    changed = load_scene(str(path))
    assert changed.params == {"k": 4.0} and changed.system is not first.system


def test_the_same_marches_from_a_scene_loaded_again(tmp_path):
    path = tmp_path / "osc.py"
    path.write_text(SCENE.format(k=2.0))
    a = load_scene(str(path)).march()
    b = load_scene(str(path)).march()
    assert a.success and np.array_equal(a.t, b.t) and np.array_equal(a.q, b.q)
    assert b.verdict.name == a.verdict.name
