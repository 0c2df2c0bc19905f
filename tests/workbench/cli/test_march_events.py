"""``ddvp march --t-eval`` and ``--event``: the states at the asked-for times and the located
crossings in the run folder, equal to the API's; event expressions evaluated by a restricted
walker that computes and never runs code."""

import json
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import InputError, Output, load_scene, march
from ddvp_nlp.cli import main
from ddvp_nlp.cli.events import ARITY, parse_event, parse_times


def run(tmp_path, *extra):
    folder = tmp_path / "run"
    code = main(["march", "harmonic", "--no-progress", "--no-plot", "--out", str(folder),
                 *extra])
    arrays = np.load(folder / "result.npz")
    return code, {k: arrays[k] for k in arrays.files}, json.loads(
        (folder / "meta.json").read_text())


def test_states_at_the_times_and_crossings_match_the_exact_motion_and_the_api(tmp_path,
                                                                               capsys):
    code, arrays, meta = run(tmp_path, "--t-eval", "0:20:41", "--event", "q1;down",
                             "--event", "p1 - 0.5*sin(t) + 0*w")
    assert code == 0
    out = capsys.readouterr().out
    assert "t_eval: the state at 41 times from 0 to 20" in out
    assert "event 0 'q1' (down): 3 crossings, first at t = 1.57" in out
    assert np.array_equal(arrays["t_eval"], np.linspace(0, 20, 41))
    # q = cos t, p = -sin t (w = 1): between the nodes, the dense output (third order) adds
    # nothing visible to the scheme's own global error (second order, growing with t)
    def error(t, q, p):
        return np.max(np.abs(np.column_stack([q - np.cos(t), p + np.sin(t)])))

    nodal = error(arrays["t"], arrays["q"][:, 0], arrays["p"][:, 0])
    between = error(arrays["t_eval"], arrays["z_eval"][:, 0], arrays["z_eval"][:, 1])
    assert between <= nodal + 0.1 ** 4  # tau0^4: the interpolant's own error
    # q1 crosses zero downward at pi/2 + 2 pi k (three before t = 20), shifted by the scheme's
    # phase error: on the unit circle, a time shift of the state error's size
    assert np.allclose(arrays["t_events_0"], np.pi / 2 + 2 * np.pi * np.arange(3), rtol=0,
                       atol=2 * nodal)
    assert np.max(np.abs(arrays["z_events_0"][:, 0])) < 1e-12  # on the event to round-off
    g = arrays["z_events_1"][:, 1] - 0.5 * np.sin(arrays["t_events_1"])
    assert arrays["t_events_1"].size >= 6 and np.max(np.abs(g)) < 1e-12
    assert meta["events"][0] == {"expression": "q1", "direction": "down", "terminal": 0,
                                 "count": 3, "times": list(arrays["t_events_0"])}
    # the API with the same requests gives the same numbers
    system = load_scene("harmonic").system
    down = lambda t, q, p: q[0]  # noqa: E731
    down.direction = -1
    solution = march(system, [1.0], [0.0], (0.0, 20.0), tau0=0.1,
                     output=Output(t_eval=np.linspace(0, 20, 41), events=[down]))
    assert np.allclose(solution.z_eval, arrays["z_eval"], rtol=0, atol=1e-12)
    assert np.allclose(solution.t_events[0], arrays["t_events_0"], rtol=0, atol=1e-12)


def test_a_terminal_event_ends_the_march_and_says_so(tmp_path, capsys):
    code, arrays, meta = run(tmp_path, "--event", "q1 + 0.5;terminal=2")
    assert code == 0 and meta["status"] == "event"
    assert meta["events"][0]["count"] == 2
    out = capsys.readouterr().out
    assert "2 crossings" in out and "ended the march" in out
    assert arrays["t"][-1] < 20.0 and arrays["t"][-2] < arrays["t_events_0"][-1]


@pytest.mark.parametrize("text, message", [
    ("__import__('os').system('echo hacked')", "is not allowed"),
    ("q1.real", "is not allowed"),
    ("q1[0]", "is not allowed"),
    ("(lambda: 1)()", "is not allowed"),
    ("open('x')", "is not allowed"),
    ("sin(q1, **{})", "is not allowed"),
    ("q3", "unknown name 'q3'"),
    ("x + 1", "unknown name 'x'"),
    ("q1 +", "not an expression"),
    ("q1;sideways", "neither up, down"),
    ("q1;terminal=0", "terminal=N needs a count"),
    ("1" + "0" * 400 + " * q1", "beyond the floating-point range"),
    ("", "--event must be"),
])
def test_an_event_expression_computes_and_never_runs_code(text, message):
    with pytest.raises(InputError, match=message):
        parse_event(text, 2, {"mu": 0.5})


def test_an_expression_evaluates_like_numpy():
    rng = np.random.default_rng(1)
    t, q, p = rng.normal(size=7), rng.normal(size=(7, 2)), rng.normal(size=(7, 2))
    g = parse_event("arctan2(q2, q1) - mu*exp(-t**2) + sqrt(abs(p1*p2)) / 3 - pi;up", 2,
                    {"mu": 0.5})
    assert g.direction == 1 and g.terminal == 0 and g.vectorized
    expected = (np.arctan2(q[:, 1], q[:, 0]) - 0.5 * np.exp(-t ** 2)
                + np.sqrt(np.abs(p[:, 0] * p[:, 1])) / 3 - np.pi)
    assert np.allclose(g(t, q, p), expected, rtol=1e-15, atol=0)
    assert np.all(np.isinf(parse_event("2.0**10000 + q1", 2, {})(t, q, p)))  # no OverflowError


def test_times_parse_and_stay_in_the_span():
    assert np.array_equal(parse_times("0:1:5", (0, 1)), np.linspace(0, 1, 5))
    assert np.array_equal(parse_times("0.5,1,2", (0, 2)), [0.5, 1, 2])
    for bad, message in (("0:3:5", "must lie in"), ("1,0.5", "increasing"), ("1,inf", "finite"),
                         ("a,b", "T1,T2"), ("0:1:0", "COUNT"), ("0:1", "T1,T2")):
        with pytest.raises(InputError, match=message):
            parse_times(bad, (0, 2))


@pytest.mark.parametrize("extra, message", [
    (["--t-eval", "0:30:5"], "--t-eval '0:30:5' must lie in t_span = [0, 20]"),
    (["--event", "q9"], "unknown name 'q9'"),
    (["--event", "q1", "--method", "rk4"], "compared method"),
    (["--event", "q1", "--resume", "nowhere"], "not to --resume"),
])
def test_bad_requests_exit_2_naming_the_option(tmp_path, extra, message, capsys):
    assert main(["march", "harmonic", "--no-plot", "--out", str(tmp_path / "x"), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


@pytest.mark.parametrize("text, message", [
    ("sin()", "sin takes 1 argument, got 0"),
    ("sin(q1, q1)", "sin takes 1 argument, got 2"),
    ("arctan2(q1)", "arctan2 takes 2 arguments, got 1"),
    ("hypot(q1, q2, p1)", "hypot takes 2 arguments, got 3"),
    ("maximum(q1, q2, q1)", "maximum takes 2 arguments, got 3"),
    ("sin(*[q1])", "is not allowed"),
    ("exp(x=q1)", "is not allowed"),
    ("-" * 300 + "q1", "nested deeper than"),
])
def test_every_function_takes_its_number_of_positional_scalars(text, message):
    """A numpy ufunc takes one argument more than its mathematics (its output array):
    'sin(q1, q1)' had written into q1 and ended the run at step 1, 'sin()' was an internal
    error; both are refused when parsed, naming the call."""
    with pytest.raises(InputError, match=re.escape(message)):
        parse_event(text, 2, {})


@pytest.mark.parametrize("event", ["sin()", "sin(q1, q1)"])
def test_a_wrong_call_exits_2_before_the_folder_is_made(tmp_path, event, capsys):
    out = tmp_path / "x"
    assert main(["march", "harmonic", "--no-plot", "--out", str(out), "--event", event]) == 2
    err = capsys.readouterr().err
    assert f"--event '{event}'" in err and "takes 1 argument" in err
    assert "Traceback" not in err and not out.exists()


# Pieces of expressions, right and wrong: the property is that any text is either refused
# with an InputError or evaluates to one real number per time, never runs code, never raises
# anything else.
_ATOMS = st.sampled_from(["q1", "q2", "p1", "p2", "t", "pi", "mu", "1", "0", "2.5", "1e308",
                          "x", "q3", "__import__", "open", "q1.real", "()", "[q1]", "''"])


@st.composite
def _expressions(draw, depth=0):
    if depth > 4 or draw(st.booleans()):
        return draw(_ATOMS)
    kind = draw(st.sampled_from(["call", "binary", "unary", "keyword", "lambda"]))
    sub = [draw(_expressions(depth=depth + 1)) for _ in range(draw(st.integers(0, 3)))]
    if kind == "call":
        name = draw(st.sampled_from([*ARITY, "eval", "getattr", "sum"]))
        return f"{name}({', '.join(sub)})"
    if kind == "binary" and sub:
        return f"({sub[0]} {draw(st.sampled_from(['+', '-', '*', '/', '**', '%', '//', '@']))} "\
               f"{sub[-1]})"
    if kind == "unary" and sub:
        return f"{draw(st.sampled_from(['-', '+', 'not ', '~']))}{sub[0]}"
    if kind == "keyword":
        return f"{draw(st.sampled_from(list(ARITY)))}(out={sub[0] if sub else 'q1'})"
    return f"(lambda: {sub[0] if sub else 1})()"


@given(text=_expressions(), modifiers=st.sampled_from(["", ";up", ";down;terminal=2", ";x"]))
@settings(max_examples=100, deadline=None, derandomize=True)  # 300 before the CPU budget
def test_any_expression_is_refused_or_evaluates_to_one_number_per_time(text, modifiers):
    t = np.linspace(0.0, 1.0, 5)
    q = np.linspace(-1.0, 1.0, 10).reshape(5, 2)
    p = q[::-1].copy()
    before = (q.copy(), p.copy())
    try:
        g = parse_event(text + modifiers, 2, {"mu": 0.5})
    except InputError as exc:
        assert str(exc).startswith("--event")
        return
    value = g(t, q, p)
    assert value.shape == t.shape and value.dtype == float
    assert np.array_equal(q, before[0]) and np.array_equal(p, before[1])  # nothing written
