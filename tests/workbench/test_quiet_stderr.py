"""No raw CasADi line reaches stderr (issue 40): a scene written with numpy's functions gets the
tool's one-line warning instead of CasADi's 20 lines about its numpy mode, and the solvers'
rootfinders and IPOPT are built without CasADi's "NaN/Inf detected ... oracle_function.cpp"
evaluation warnings (a failed step is reported in the tool's own words)."""

import os
import subprocess
import sys
from pathlib import Path

import casadi as ca

from ddvp_nlp.solvers.grid.ipopt import ipopt_settings
from ddvp_nlp.solvers.marching.step_newton import NEWTON_OPTIONS

ROOT = Path(__file__).resolve().parents[2]
CASADI_LINES = ("CasADi -", "oracle_function", "casadi:", "setNumpyMode", "issue #2959")

NUMPY_SCENE = '''
import numpy as np
from ddvp_nlp import Scene

def hamiltonian(q, p, t):
    return p[0] ** 2 / 2 - np.cos(q[0]) + np.exp(0 * q[0])

scene = Scene(hamiltonian, n=1, q0=[0.5], p0=[0.0], tau0=0.05, t_end=2.0)
'''


def test_a_scene_using_numpy_gets_one_line_of_ours(tmp_path, capfd):
    """The command as a user runs it (its own process, its warning format): stderr holds our
    line and nothing of CasADi's."""
    scene = tmp_path / "np_pendulum.py"
    scene.write_text(NUMPY_SCENE)
    done = subprocess.run([sys.executable, "-m", "ddvp_nlp.cli", "march", str(scene),
                           "--no-plot", "--no-progress", "--out", str(tmp_path / "run")],
                          capture_output=True, text=True, cwd=tmp_path,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    err = done.stderr
    assert done.returncode == 0, err
    assert not [line for line in err.splitlines() if any(s in line for s in CASADI_LINES)], err
    assert err.splitlines() == [
        "ddvp: warning: hamiltonian of 'np_pendulum' uses numpy's functions on CasADi symbols "
        "(np_pendulum.py:6: np.cos, np.exp); use casadi's (ca.cos, ca.exp, ...) instead"], err


def test_rootfinders_and_ipopt_keep_casadi_evaluation_warnings_off(capfd):
    x = ca.SX.sym("x")
    residual = ca.Function("g", [x], [ca.log(x) + 1])
    ca.rootfinder("r", "newton", residual, dict(NEWTON_OPTIONS))(-1.0)  # NaN at the start
    assert "NaN detected" not in capfd.readouterr().err
    ca.rootfinder("r", "newton", residual)(-1.0)  # CasADi's default: the line this removes
    assert "NaN detected" in capfd.readouterr().err
    assert ipopt_settings(1e-9, 10, False, None, {})["show_eval_warnings"] is False
    assert ipopt_settings(1e-9, 10, True, None, {})["show_eval_warnings"] is True
