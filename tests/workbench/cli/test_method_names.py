"""``ddvp march --method`` lists the compared methods without importing them: the parser's
written-out names (``cli/parser.py``, ``COMPARED_METHODS``) are the registry's, in its order."""

import json
import subprocess
import sys

from ddvp_nlp.cli.one_run import method_names
from ddvp_nlp.cli.parser import COMPARED_METHODS, build_parser
from ddvp_nlp.discrete import RULES
from ddvp_nlp.studies.methods import METHODS


def test_the_written_out_names_are_the_registrys():
    assert COMPARED_METHODS == tuple(name for name in METHODS if name not in RULES)
    assert method_names() == COMPARED_METHODS


def test_the_march_parser_offers_exactly_those_names():
    march = build_parser("march").commands["march"]
    (action,) = [a for a in march._actions if "--method" in a.option_strings]
    assert tuple(action.choices) == COMPARED_METHODS


def test_a_marchs_parser_imports_no_method():
    code = ("from ddvp_nlp.cli.parser import build_parser\nbuild_parser('march')\n"
            "import sys, json\nprint(json.dumps(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                         text=True).stdout
    modules = json.loads(out.strip().splitlines()[-1])
    assert [m for m in modules if m.startswith(("ddvp_nlp.studies",
                                                "ddvp_nlp.solvers.baselines"))] == []
