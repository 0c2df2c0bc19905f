"""The one block loop (``ddvp_nlp/blocks.py``): any width, halo, fill of the last block and
output length gives the rows one whole evaluation gives, bit for bit (a documented property:
each row is computed alone), in place or through a `Sink`."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp.blocks import Sink, copied, evaluate_in_blocks


def row_function(x):
    """Row i from rows i and i + 1 (a halo of one): what a node equation reads."""
    return np.sin(x[:-1]) * 3.0 + x[1:] ** 2


@settings(max_examples=60, derandomize=True, deadline=None, database=None)
@given(st.integers(1, 40), st.integers(1, 9), st.sampled_from(["pad", "shift"]),
       st.integers(0, 1), st.integers(0, 2**32 - 1))
def test_blocks_give_the_rows_of_one_whole_evaluation(count, width, last, short, seed):
    x = np.random.default_rng(seed).normal(size=(count + 1, 2))
    whole = row_function(x)[:count - short]
    out = np.full((count - short, 2), np.nan)
    received = {}
    sink = Sink((2,), lambda first, rows: received.update(
        {first + i: row.copy() for i, row in enumerate(rows)}))
    evaluate_in_blocks(copied(lambda block: (row_function(block), row_function(block))),
                       [x], [out, sink], count=count, width=width, last=last, halo=1)
    assert np.array_equal(out, whole)
    assert sorted(received) == list(range(count))
    kept = np.array([received[i] for i in range(count - short)]).reshape(-1, 2)
    assert np.array_equal(kept, whole)


def test_an_unknown_fill_is_refused():
    with pytest.raises(ValueError, match="last must be 'pad' or 'shift'"):
        evaluate_in_blocks(lambda i, o: None, [np.zeros((3, 1))], [], count=3, width=2,
                           last="wrap")
