"""A number's range is checked in one place, the option object (or the study) it stands for,
which names its field; the command line says the same with the flag (``cli/flags.py``). Drawn
values: every non-finite or non-positive value of a positive option is refused, by name, before
anything is built (issue 45: ``--stability-tol nan`` had been taken)."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp import GridOptions, Output, StepControl, Tolerance
from ddvp_nlp.cli.arguments import check_options
from ddvp_nlp.cli.flags import FLAGS, in_flags
from ddvp_nlp.cli.parser import build_parser, parse_arguments
from ddvp_nlp.cli.request import Request
from ddvp_nlp.errors import InputError
from ddvp_nlp.solvers import Continuation

pytestmark = pytest.mark.smoke  # no solver is built: the quick tier (tests/README.md)

# Every positive real option of every command, as (command, the words before it, option).
POSITIVE = [
    *[("march", ["harmonic"], option) for option in (
        "tol", "tau-min", "tau-max", "time-limit", "energy-guard", "rtol", "atol",
        "energy-tol", "global-tol", "checkpoint-every", "max-step-ratio")],
    *[("bvp", ["pendulum"], option) for option in ("tol", "time-limit", "rtol", "global-tol")],
    *[("periodic", ["harmonic"], option) for option in (
        "stability-tol", "step", "rtol", "atol", "energy-tol")],
    ("poincare", ["henon_heiles", "--energy", "0.1"], "tau0"),
    ("poincare", ["henon_heiles", "--energy", "0.1"], "global-tol"),
    *[("compare", ["harmonic"], option) for option in (
        "time-unit", "run-budget", "reference-span")],
    ("stress", [], "time-limit"),
    ("sweep", ["harmonic"], "time-limit"),
]
BAD = st.one_of(st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0]),
                st.floats(max_value=0.0, allow_nan=False))


def _request(command: str, words: list[str]) -> Request:
    parser = build_parser(command)
    args = parse_arguments(parser, [command, *words])
    return Request.read(args, parser.commands[command])


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(st.sampled_from(POSITIVE), BAD)
def test_a_bad_positive_option_is_refused_by_its_flag(case, value):
    command, words, option = case
    request = _request(command, [*words, f"--{option}={value!r}"])
    with pytest.raises(InputError) as refused:
        check_options(request)
    assert str(refused.value).startswith(f"--{option} must be "), str(refused.value)
    assert ("finite" if not math.isfinite(value) else "> 0") in str(refused.value)


# Every count of an option object, as (command, the words before it, option, least value).
COUNTS = [("march", ["harmonic"], "keep-every", 1), ("march", ["harmonic"], "max-steps", 1),
          ("periodic", ["harmonic"], "max-orbits", 2), ("compare", ["harmonic"], "halvings", 0),
          ("compare", ["harmonic"], "repeats", 1), ("compare", ["harmonic"], "max-steps", 1),
          ("stress", [], "max-steps", 1), ("stress", [], "workers", 1),
          ("poincare", ["henon_heiles", "--energy", "0.1"], "workers", 1)]


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(st.sampled_from(COUNTS), st.integers(-10**6, 1))
def test_a_count_below_its_least_is_refused_by_its_flag(case, value):
    command, words, option, least = case
    request = _request(command, [*words, f"--{option}={value}"])
    if value >= least:
        check_options(request)
        return
    with pytest.raises(InputError) as refused:
        check_options(request)
    assert str(refused.value).startswith(f"--{option} must be "), str(refused.value)


FIELDS = [(StepControl, name) for name in ("tol", "tau_min", "tau_max", "max_step_ratio",
                                           "time_limit", "energy_guard")] + \
    [(Tolerance, name) for name in ("rtol", "atol", "energy_tol", "global_tol")] + \
    [(GridOptions, name) for name in ("tol", "tau_floor", "time_limit")] + \
    [(Output, "checkpoint_interval"), (Continuation, "tol"), (Continuation, "step"),
     (Continuation, "min_step"), (Continuation, "locate_tol")]


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(st.sampled_from(FIELDS), BAD)
def test_a_bad_positive_field_is_refused_by_its_name(case, value):
    kind, name = case
    with pytest.raises(InputError) as refused:
        kind(**{name: value})
    assert str(refused.value).startswith(f"{name} must be "), str(refused.value)


def test_every_flag_in_the_table_is_an_option_of_the_command_line():
    options = set()
    for command, sub in build_parser().commands.items():
        sub = build_parser(command).commands[command]
        options |= {flag for action in sub._actions for flag in action.option_strings}
    assert sorted(set(FLAGS.values()) - options) == []


@pytest.mark.parametrize("text, owner, said", [
    ("tau_min must be < tau_max = 0.01, got 0.1", None,
     "--tau-min must be < --tau-max = 0.01, got 0.1"),
    ("tol must be finite, got nan", "Continuation", "--stability-tol must be finite, got nan"),
    ("tol must be finite, got nan", None, "--tol must be finite, got nan"),
    ("grid must give q2 and p2, got 'x'", "chaos_map", "--grid must give q2 and p2, got 'x'"),
    ("grid must give q2 and p2, got 'x'", None, "grid must give q2 and p2, got 'x'"),
    ("folder 'p': no shard-K-of-N folder in it (run the shards with `shard` K/N `out` there "
     "first)", "merge_shards", "--merge 'p': no shard-K-of-N folder in it (run the shards "
     "with --shard K/N --out there first)"),
    ("scene 'lag' starts from v0; the comparison needs p0 (`settings` p0=...)", "comparison",
     "scene 'lag' starts from v0; the comparison needs p0 (--set p0=...)"),
    ("target_errors gives 0.5 twice", None, "--target-errors gives 0.5 twice"),
    ("keep must be one of nodes, t_eval, got 'x'", None,
     "keep must be one of nodes, t_eval, got 'x'"),
])
def test_a_message_is_said_with_the_flags_of_its_fields(text, owner, said):
    assert in_flags(text, owner) == said
