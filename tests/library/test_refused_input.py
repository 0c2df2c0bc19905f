"""Bad input: a clear error naming the argument and the value, before anything is built."""

import re

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import (
    GridOptions,
    HamiltonianSystem,
    InputError,
    Scheme,
    StepControl,
    load_scene,
    march,
    solve_bvp,
)

pytestmark = pytest.mark.smoke  # the quick tier: tests/README.md


@pytest.fixture(scope="module")
def pendulum():
    return load_scene("pendulum").system


def expect(message):
    return pytest.raises(InputError, match="^" + re.escape(message) + "$")


@pytest.mark.parametrize("kwargs, message", [
    ({"q0": [np.nan]}, "q0 must be finite, got [nan]"),
    ({"p0": [np.inf]}, "p0 must be finite, got [inf]"),
    ({"q0": [0.1, 0.2]}, "q0 must have shape (1,), got shape (2,): [0.1, 0.2]"),
    ({"p0": []}, "p0 must have shape (1,), got shape (0,): []"),
    ({"q0": "abc"}, "q0 must be an array of 1 real numbers, got 'abc'"),
    ({"tau0": 0.0}, "tau0 must be > 0, got 0.0"),
    ({"tau0": -0.1}, "tau0 must be > 0, got -0.1"),
    ({"tau0": float("nan")}, "tau0 must be finite, got nan"),
    ({"tau0": 20.0}, "tau0 must not exceed |t_end - t0| = 10.0, got 20.0"),
    ({"t_end": 0.0}, "t_end must be > t0 = 0.0, got 0.0"),
    ({"t_end": -1.0, "tau0": 2.0}, "tau0 must not exceed |t_end - t0| = 1.0, got 2.0"),
    ({"scheme": "euler"}, "unknown scheme 'euler' (choose from vddvp, lee, fixed)"),
    ({"tol": 0.0}, "tol must be > 0, got 0.0"),
    ({"max_steps": 0}, "max_steps must be a positive integer, got 0"),
    ({"tau_min": 0.2, "tau_max": 0.1}, "tau_min must be < tau_max = 0.1, got 0.2"),
    ({"tau_min": -1.0}, "tau_min must be > 0, got -1.0"),
    ({"params": {"g": 9.81}}, "system 'pendulum' has no parameter 'g' (its parameters: none)"),
])
def test_march_rejects_bad_input(pendulum, kwargs, message):
    options = {"q0": [0.5], "p0": [0.5], "tau0": 0.05, "t0": 0.0, "t_end": 10.0, **kwargs}
    with expect(message):
        span = (options.pop("t0"), options.pop("t_end"))
        steps = {k: options.pop(k) for k in ("tol", "max_steps", "tau_min", "tau_max")
                 if k in options}
        march(pendulum, options.pop("q0"), options.pop("p0"), span,
              steps=StepControl(**steps), **options)


def test_parameter_of_wrong_type():
    system = load_scene("harmonic").system
    with expect("parameter 'w' must be a real number, got 'fast' of type str"):
        march(system, [1.0], [0.0], (0.0, 1.0), tau0=0.1, params={"w": "fast"})


def test_hamiltonian_not_scalar():
    with expect("hamiltonian of 'vector' must be scalar, got shape 2x1"):
        HamiltonianSystem(lambda q, p, t: p**2 / 2, n=2, name="vector")


def test_hamiltonian_with_a_foreign_symbol():
    stray = ca.SX.sym("k")
    with expect("hamiltonian of 'leaky' depends on symbols it was not given: k"):
        HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 + stray * q[0] ** 2, n=1, name="leaky")


def test_hamiltonian_that_raises():
    def broken(q, p, t):
        return q[5]
    with pytest.raises(InputError, match="^hamiltonian of 'broken' failed on symbolic input: "):
        HamiltonianSystem(broken, n=1, name="broken")


def test_hamiltonian_not_finite_at_the_initial_state():
    system = HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 - 1 / q[0], n=1, name="coulomb")
    with expect("H is not finite at the initial state q0=[0.0], p0=[1.0], t0=0.0: H = -inf"):
        march(system, [0.0], [1.0], (0.0, 1.0), tau0=0.1)


def test_alpha_out_of_range():
    with expect("alpha must be a number in [0, 1], got 1.5"):
        Scheme("vddvp", alpha=1.5)


def test_unknown_scene_names_the_built_in_ones():
    with pytest.raises(InputError, match=re.escape("unknown scene 'pendulm'; did you mean "
                                                   "'pendulum'")):
        load_scene("pendulm")
    with pytest.raises(InputError, match=re.escape(
            "(built-in scenes: barbanis, cartesian_pendulum, cr3bp, figure_eight, four_bar, fpu, "
            "harmonic, "
            "henon_heiles, hill, kepler, pais_uhlenbeck, paper_pendulum, pendulum, "
            "pendulum_lagrangian, spherical_pendulum, spline; or a .py file)")):
        load_scene("pendulm")
    with pytest.raises(InputError) as far:  # nothing close: no guess
        load_scene("zzzz")
    assert "did you mean" not in str(far.value)


def test_scene_parameter_unknown():
    with expect("scene 'kepler' has no parameter 'mass' (it has: e, t0, tau0, t_end, q0, p0)"):
        load_scene("kepler").resolve({"mass": 1.0})


def test_scene_file_that_does_not_load(tmp_path):
    path = tmp_path / "bad.py"
    path.write_text("import nonexistent_module_xyz\n")
    with expect(f"scene file {str(path)!r}, line 1: loading the file raised "
                "ModuleNotFoundError: No module named 'nonexistent_module_xyz'"):
        load_scene(str(path))


def test_scene_file_without_scene(tmp_path):
    path = tmp_path / "empty.py"
    path.write_text("x = 1\n")
    with expect(f"scene file {str(path)!r} defines no `scene = Scene(...)`"):
        load_scene(str(path))


@pytest.mark.parametrize("kwargs, message", [
    ({"q_start": []}, "q_start must have shape (1,), got shape (0,): []"),
    ({"q_start": [[0.5]]}, "q_start must have shape (1,), got shape (1, 1): [[0.5]]"),
    ({"q_end": [np.inf]}, "q_end must be finite, got [inf]"),
    ({"t_end": np.nan}, "t_end must be finite, got nan"),
    ({"nodes": 2.5}, "nodes must be an integer >= 3, got 2.5"),
    ({"tol": float("nan")}, "tol must be finite, got nan"),
    ({"tol": -1e-9}, "tol must be > 0, got -1e-09"),
    ({"scheme": "verlet"}, "unknown scheme 'verlet' (choose from vddvp, lee, fixed)"),
    ({"params": {"w": "1"}}, "system 'pendulum' has no parameter 'w' (its parameters: none)"),
])
def test_solve_bvp_rejects_bad_input(pendulum, kwargs, message):
    options = {"q_start": [0.5], "q_end": [-0.036], "t0": 0.0, "t_end": 9.0, "nodes": 20,
               **kwargs}
    with expect(message):
        span = (options.pop("t0"), options.pop("t_end"))
        grid = GridOptions(tol=options.pop("tol")) if "tol" in options else None
        solve_bvp(pendulum, options.pop("q_start"), options.pop("q_end"), span, options=grid,
                  **options)


def test_parameter_value_of_the_wrong_type_in_a_scene():
    scene = load_scene("kepler")
    with expect("parameter 'e' must be a real number, got '0.5' of type str"):
        scene.resolve({"e": "0.5"})


def test_scene_settings_as_objects_or_plain_forms():
    """A scene's fixed-endpoint and periodic defaults are their dataclasses, or the plain
    forms the docs write (a dict of fields; a tuple for boundary), made into the same objects
    with the same checks; anything else, an unknown field or a bad value is refused by name."""
    from ddvp_nlp import Endpoints, PeriodicSettings, Scene

    def H(q, p, t):
        return (p[0] ** 2 + q[0] ** 2) / 2

    def scene(**kwargs):
        return Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=1.0, **kwargs)

    made = scene(boundary=Endpoints(q_start=[1.0], q_end=[0.0], t_span=(0.0, 1.0)),
                 periodic=PeriodicSettings(energy=0.5))
    assert made.resolve_boundary({}).nodes == 101 and made.periodic.section == "p1=0"
    plain = scene(boundary={"q_start": [1.0], "q_end": [0.0], "t_span": (0.0, 1.0)},
                  periodic={"energy": 0.5, "angles": ["q1"],
                            "families": {"other": {"section": "q1=0"}}})
    assert plain.boundary == made.boundary and plain.periodic.energy == 0.5
    assert plain.periodic.angles == ("q1",)
    assert plain.periodic.families["other"] == PeriodicSettings(section="q1=0")
    assert scene(boundary=([1.0], [0.0], (0.0, 1.0), 21)).resolve_boundary({}).nodes == 21
    with expect("scene 'scene': boundary: unknown field 'node' of Endpoints (known: q_start, "
                "q_end, t_span, nodes)"):
        scene(boundary={"node": 5})
    with expect("scene 'scene': periodic: unknown field 'energie' of PeriodicSettings (known: "
                "section, energy, nodes, start, integrals, angles, families, guess, period)"):
        scene(periodic={"energie": 0.5})
    with expect("scene 'scene': periodic must be PeriodicSettings(...), a dict of its fields, "
                "or None, got 0.5"):
        scene(periodic=0.5)
    with expect("scene 'scene': periodic: PeriodicSettings energy must be a real number, got "
                "'0.5'"):
        scene(periodic={"energy": "0.5"})
    with pytest.raises(InputError, match=re.escape(
            "scene 'scene': periodic: PeriodicSettings families['x']: unknown field")):
        scene(periodic={"families": {"x": {"sections": "q1=0"}}})
    with expect("scene 'scene': boundary: Endpoints nodes must be an integer >= 2, got 1"):
        scene(boundary={"nodes": 1})
    with expect("scene 'scene': boundary: t_end must be > t0 = 1.0, got 0.0"):
        scene(boundary=([1.0], [0.0], (1.0, 0.0)))
