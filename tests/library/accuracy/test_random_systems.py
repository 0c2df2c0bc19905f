"""The accuracy verdict on systems nobody chose, judged against an independent reference.

Hypothesis draws random Hamiltonians (``studies/verdict_study.py``: polynomial and trigonometric
potentials in 1-3 degrees of freedom with couplings, non-separable terms, forcing and gauge
terms), starts, first steps across the breakdown range, schemes and units from 1e-4 to 1e4
with offsets; each case is marched, its verdict set beside its true error against scipy's
DOP853 at rtol 1e-12 with dense output. No false success (``accurate`` with a true error above
twice the tolerance), no false refusal (``drifted`` or ``inaccurate`` with a true error below
half of it): the definitions of ``studies.verdicts.classify``. The cases are drawn
deterministically (``derandomize``), a fixed number of them; the 1000-case study is
``scripts/pages/accuracy_study.py`` (docs/accuracy/README.md)."""

import pytest
from helpers.random_cases import cases
from hypothesis import HealthCheck, given, settings

from ddvp_nlp.studies.verdict_study import judge_case

CASES = 60


@pytest.mark.slow(why="study")
@settings(max_examples=CASES, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(cases())
def test_no_false_success_and_no_false_refusal_on_random_systems(case):
    row = judge_case(case)
    assert row["class"] not in ("false success", "false refusal"), (row, case.describe())


@settings(max_examples=15, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(cases())
def test_a_few_random_systems_get_no_false_verdict(case):
    """The same property on fifteen drawn systems, in every default run (CI): the
    package's central claim is checked on cases nobody chose at every change, the study above
    on sixty."""
    row = judge_case(case)
    assert row["class"] not in ("false success", "false refusal"), (row, case.describe())
