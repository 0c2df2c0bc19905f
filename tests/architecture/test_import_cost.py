"""What ``import ddvp_nlp`` loads: the base, the systems, the scenes and the option objects, not
the solvers (they load on first use, PEP 562), and a march loads no fixed-endpoint solver and
neither ``scipy.sparse`` nor ``scipy.linalg``. Counted in modules, never in seconds."""

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.smoke  # the quick tier: tests/README.md

SOLVER_FAMILIES = ("ddvp_nlp.solvers.bvp", "ddvp_nlp.solvers.grid", "ddvp_nlp.solvers.periodic",
                   "ddvp_nlp.solvers.higher", "ddvp_nlp.solvers.marching",
                   "ddvp_nlp.solvers.baselines")
HEAVY = ("scipy.sparse", "scipy.linalg", "scipy.interpolate", "scipy.optimize", "matplotlib")
# ddvp_nlp's own modules after `import ddvp_nlp` (14 when this test was written; 58 when every
# family was imported eagerly; 21 once the base layer held the one block loop and the one
# safe-file module and a scene's run configuration had its own module: small modules the
# package had already loaded as parts of cache.py, validation.py and scenes/scene.py)
MOST_OWN_MODULES = 21


def loaded(code: str) -> list[str]:
    """The modules a fresh interpreter holds after running ``code``."""
    out = subprocess.run([sys.executable, "-c", f"{code}\nimport sys, json\n"
                          "print(json.dumps(sorted(sys.modules)))"],
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def _under(modules, prefixes):
    return [m for m in modules if any(m == p or m.startswith(p + ".") for p in prefixes)]


def test_import_loads_no_solver_family_and_no_heavy_scipy_part():
    modules = loaded("import ddvp_nlp")
    assert _under(modules, SOLVER_FAMILIES) == []
    assert _under(modules, HEAVY) == []
    assert len([m for m in modules if m.startswith("ddvp_nlp")]) <= MOST_OWN_MODULES


def test_a_march_loads_no_fixed_endpoint_solver():
    modules = loaded("import ddvp_nlp\nfrom ddvp_nlp import load_scene, march\n"
                     "march(load_scene('harmonic').system, [1.0], [0.0], (0.0, 1.0), tau0=0.1)")
    assert "ddvp_nlp.solvers.marching.initial_value" in modules
    assert _under(modules, ("ddvp_nlp.solvers.bvp", "ddvp_nlp.solvers.grid",
                            "ddvp_nlp.solvers.periodic", "ddvp_nlp.solvers.higher")) == []
    assert _under(modules, ("scipy.sparse", "scipy.linalg")) == []


def test_every_public_solver_is_loaded_when_asked_for():
    modules = loaded("from ddvp_nlp import solve_bvp, solve_periodic, march_higher, Shooting")
    assert {"ddvp_nlp.solvers.bvp.fixed_ends", "ddvp_nlp.solvers.periodic.orbit",
            "ddvp_nlp.solvers.higher.stepping"} <= set(modules)


def test_listing_the_scenes_loads_no_solver_family_and_no_heavy_scipy_part():
    """``ddvp scenes`` runs every built-in scene file; a scene that uses a solver or scipy in a
    guess or a root does so when asked, not as it loads (it took 1.38 s of CPU with
    scipy.optimize, scipy.interpolate and the periodic solvers loaded; 0.87 s without).
    scipy.special stays: the loader probes the pendulum's exact solution, which uses it."""
    modules = loaded("import contextlib, io\nfrom ddvp_nlp.cli.main import main\n"
                     "with contextlib.redirect_stdout(io.StringIO()):\n    main(['scenes'])")
    assert "ddvp_nlp.cli.scenes_command" in modules
    assert _under(modules, SOLVER_FAMILIES) == []
    assert _under(modules, HEAVY) == []
