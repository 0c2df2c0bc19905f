"""What the compiled code changes in CasADi's generated C (``compiler.py``): its ``fmax``
written inline and the march's chunk as one loop over its step. Both are the same arithmetic,
so the compiled functions give the virtual machine's outputs to the bit."""

import ctypes
import ctypes.util

import casadi as ca
import numpy as np
import pytest

from ddvp_nlp import load_scene
from ddvp_nlp.discrete.scheme import Scheme
from ddvp_nlp.solvers.compiler import (
    cache_folder,
    compile_function,
    find_compiler,
    generated_code,
    looped_mapaccum,
)
from ddvp_nlp.solvers.marching.acceptance import Acceptance
from ddvp_nlp.solvers.marching.chunk import FastChunk
from ddvp_nlp.solvers.marching.steps import step_functions

COMPILER = find_compiler()
pytestmark = pytest.mark.skipif(COMPILER is None, reason="no C compiler on this machine")

SPECIAL = [0.0, -0.0, 1.0, -1.0, np.inf, -np.inf, np.nan, -np.nan, 5e-324, -5e-324, 2.5]


def _bits(values) -> np.ndarray:
    return np.asarray(values, dtype=float).view(np.int64)


def test_the_inline_fmax_returns_what_libm_returns_for_every_special_pair():
    """The same values as the C library's ``fmax`` (what the compiled code called before), NaN
    where it gives NaN; a zero's sign may differ from another C library's (glibc's x86-64
    fmax and the inline one return ``y`` for ``fmax(0, -0)``, CasADi's virtual machine ``x``):
    no comparison sees it."""
    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    libm.fmax.restype, libm.fmax.argtypes = ctypes.c_double, [ctypes.c_double] * 2
    pairs = [(x, y) for x in SPECIAL for y in SPECIAL]
    x, y = ca.SX.sym("x", len(pairs)), ca.SX.sym("y", len(pairs))
    function = ca.Function("fmax_pairs", [x, y], [ca.fmax(x, y)])
    code = generated_code(function)
    assert "return fmax(x, y);" not in code and "larger" in code  # the call replaced
    # in the default cache: a library there is named by the hash of this code (the inline
    # fmax in it), the compiler and its flags, so a loaded one is this code compiled
    compiled = compile_function(function, COMPILER, cache_folder())
    a, b = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    found = np.asarray(compiled(a, b)).ravel()
    expected = np.array([libm.fmax(p, q) for p, q in pairs])
    nan = np.isnan(expected)
    assert np.array_equal(np.isnan(found), nan)
    assert np.array_equal(found[~nan], expected[~nan])
    zero = expected == 0
    assert np.array_equal(_bits(found[~nan & ~zero]), _bits(expected[~nan & ~zero]))


def test_a_mapaccum_generated_as_a_loop_gives_its_tree_s_outputs_to_the_bit():
    state, p = ca.SX.sym("state", 2), ca.SX.sym("p", 3)
    after = ca.vertcat(state[1] * p[0] + ca.sin(state[0]), state[0] - p[1] * state[1])
    step = ca.Function("step", [state, p], [after, ca.vertcat(ca.fmax(after[0], p[2]),
                                                               after[1], state[0])])
    function = step.mapaccum("toy_chunk", 37)
    code = generated_code(function)
    looped = looped_mapaccum(code, function, 37)
    assert "ddvp_looped" in looped and looped != code
    compiled = compile_function(function, COMPILER, cache_folder(), steps=37)
    rng = np.random.default_rng(3)
    start, parameters = rng.normal(size=2), rng.normal(size=(3, 37))
    for found, expected in zip(compiled(start, parameters), function(start, parameters),
                               strict=True):
        assert np.array_equal(np.asarray(found), np.asarray(expected))


def test_code_of_another_shape_is_left_as_generated():
    x = ca.SX.sym("x")
    function = ca.Function("not_mapped", [x], [x * x])
    code = generated_code(function)
    assert looped_mapaccum(code, function, 4) == code


@pytest.mark.slow(why="repetition")  # the toy mapaccum above checks the loop in the default run
@pytest.mark.parametrize("name", ["paper_pendulum", "henon_heiles"])
def test_the_march_chunk_compiled_as_a_loop_is_its_virtual_machine_to_the_bit(tmp_path, name):
    scene = load_scene(name)
    config = scene.resolve({})
    system, scheme = scene.system, Scheme()
    theta = system.parameter_vector(config.params)
    first = scene.march(t_end=2 * config.tau0, accuracy=None)
    vm = FastChunk(system, scheme, step_functions(system, scheme), chunk=48, compiler=None,
                   cache_dir=tmp_path)
    compiled = FastChunk(system, scheme, step_functions(system, scheme), chunk=48,
                         compiler=COMPILER, cache_dir=tmp_path)
    assert compiled.path == "compiled"
    z = np.hstack([first.q, first.p])
    acceptance = Acceptance(tol=1e-10)
    runs = [chunk.energy_steps(first.t[0], first.t[1], z[0], z[1], 0.0, theta, acceptance)
            for chunk in (vm, compiled)]
    assert runs[0].good.all()
    for field in ("t_next", "z_next", "canonical", "energy", "H_node", "w_node", "drift"):
        assert np.array_equal(getattr(runs[0], field), getattr(runs[1], field)), field
