"""The one block evaluator (ddvp_nlp/blocks.py): a function of one block of rows evaluated over
any number of rows gives what one call over all the rows gives, bit for bit (a mapped function
computes each row alone: the documented property), whatever the block's width, however the
last block is filled, with rows read past the block (``halo``) and outputs handed to a sink."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp.blocks import (
    Sink,
    copied,
    evaluate_columns,
    evaluate_in_blocks,
    through_buffer,
)

SETTINGS = settings(max_examples=25, derandomize=True, deadline=None)


def node_function() -> ca.Function:
    """``(x (2), y (1), theta (2)) -> (u (2), v (1))``: rounding-sensitive arithmetic (a
    reordered sum or a fused multiply-add would change the bits)."""
    x, y, theta = ca.SX.sym("x", 2), ca.SX.sym("y"), ca.SX.sym("theta", 2)
    u = ca.sin(x * y) / (1 + x ** 2) + theta * ca.exp(-y)
    v = ca.log(1 + ca.sumsqr(x)) * theta[0] - y ** 3 / 7
    return ca.Function("node", [x, y, theta], [u, v])


def whole(function: ca.Function, inputs, theta):
    """One call of ``function`` over every row at once (rows out)."""
    count = inputs[0].shape[0]
    out = function.map(count)(*(a.T for a in inputs), np.tile(theta[:, None], count))
    return [np.array(o.full()).T for o in (out if isinstance(out, (list, tuple)) else [out])]


def draw(count: int, seed: int):
    rng = np.random.default_rng(seed)
    return [rng.uniform(-3, 3, (count, 2)), rng.uniform(-2, 2, (count, 1))], \
        rng.uniform(-1, 1, 2)


@SETTINGS
@given(count=st.integers(1, 300), width=st.integers(1, 70),
       last=st.sampled_from(["pad", "shift"]), seed=st.integers(0, 2 ** 16))
def test_blocks_through_a_buffer_give_one_whole_calls_bits(count, width, last, seed):
    function = node_function()
    inputs, theta = draw(count, seed)
    buffer, trigger = function.map(width).buffer()
    shared = np.tile(theta, width)
    buffer.set_arg(2, memoryview(shared))
    outputs = [np.empty((count, 2)), np.empty((count, 1))]
    evaluate_in_blocks(through_buffer(buffer, trigger), inputs, outputs, count=count,
                       width=width, last=last)
    for got, expected in zip(outputs, whole(function, inputs, theta), strict=True):
        assert np.array_equal(got, expected)


@SETTINGS
@given(count=st.integers(1, 300), width=st.integers(1, 70), seed=st.integers(0, 2 ** 16))
def test_blocks_of_returned_arrays_give_one_whole_calls_bits(count, width, seed):
    """``copied``: a call that returns its block's arrays (a ``(width, 1)`` output kept as
    a vector)."""
    function = node_function()
    inputs, theta = draw(count, seed)
    mapped = function.map(width)
    thetas = np.tile(theta[:, None], width)

    def call(x, y):
        return [np.array(o.full()).T for o in mapped(x.T, y.T, thetas)]

    u, v = np.empty((count, 2)), np.empty(count)
    evaluate_in_blocks(copied(call), inputs, [u, v], count=count, width=width)
    expected = whole(function, inputs, theta)
    assert np.array_equal(u, expected[0])
    assert np.array_equal(v, expected[1][:, 0])


@SETTINGS
@given(nodes=st.integers(3, 200), width=st.integers(1, 40), seed=st.integers(0, 2 ** 16))
def test_a_block_reading_rows_past_itself_gives_every_rows_bits(nodes, width, seed):
    """``halo=2``: a block of ``width`` rows reads ``width + 2`` nodes (a second difference at
    the node after each row); the second output has one row fewer than the first, as the
    energy equations of a grid have."""
    z0, z1, z2 = ca.SX.sym("z0"), ca.SX.sym("z1"), ca.SX.sym("z2")
    step = ca.Function("step", [z0, z1, z2], [ca.sin(z1 - z0), (z2 - 2 * z1 + z0) / 3])
    Z = ca.SX.sym("Z", width + 2)
    first, second = step.map(width)(Z[:width].T, Z[1:width + 1].T, Z[2:].T)
    block = ca.Function("block", [Z], [first.T, second.T])
    z = np.random.default_rng(seed).uniform(-5, 5, nodes)
    a, b = np.empty(nodes - 1), np.empty(nodes - 2)

    def call(values):
        return [np.array(o.full()) for o in block(values)]

    evaluate_in_blocks(copied(call), [z], [a, b], count=nodes - 1, width=width, halo=2)
    expected_a = np.array(step.map(nodes - 2)(z[:-2], z[1:-1], z[2:])[0].full()).ravel()
    expected_b = np.array(step.map(nodes - 2)(z[:-2], z[1:-1], z[2:])[1].full()).ravel()
    last = np.array(step(z[-2], z[-1], z[-1])[0].full()).ravel()
    assert np.array_equal(a, np.r_[expected_a, last])
    assert np.array_equal(b, expected_b)


@pytest.mark.parametrize("last", ["pad", "shift"])
@pytest.mark.parametrize("count", [1, 5, 16, 37])
def test_a_sink_receives_every_row(last, count):
    """A `Sink` gets each block's rows with their first index: together they are every row
    (the shifted last block gives some twice, with the same values)."""
    values = np.arange(count, dtype=float)[:, None] * np.array([[1.0, -2.0]])
    seen = np.full((count, 2), np.nan)
    calls = []

    def receive(first, rows):
        calls.append((first, rows.shape[0]))
        seen[first:first + rows.shape[0]] = rows

    def evaluate(inputs, outputs):
        outputs[0][...] = inputs[0] * np.array([1.0, -2.0])

    evaluate_in_blocks(evaluate, [values[:, :1]], [Sink((2,), receive)], count=count, width=8,
                       last=last)
    assert np.array_equal(seen, values)
    assert all(rows == (8 if last == "shift" and count >= 8 else min(8, count - first))
               for first, rows in calls)


def test_the_last_block_is_never_read_past_the_rows():
    """A short last block is padded with its last row, never read past the array."""
    values = np.arange(10, dtype=float)[:, None]
    blocks = []
    evaluate_in_blocks(lambda inputs, outputs: blocks.append(inputs[0][:, 0].copy()), [values],
                       [], count=10, width=4)
    assert [b.tolist() for b in blocks] == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 9, 9]]
    blocks.clear()
    evaluate_in_blocks(lambda inputs, outputs: blocks.append(inputs[0][:, 0].copy()), [values],
                       [], count=10, width=4, last="shift")
    assert [b.tolist() for b in blocks] == [[0, 1, 2, 3], [4, 5, 6, 7], [6, 7, 8, 9]]
    with pytest.raises(ValueError, match="last must be"):
        evaluate_in_blocks(lambda inputs, outputs: None, [values], [], count=10, width=4,
                           last="wrap")


@SETTINGS
@given(count=st.integers(1, 600), seed=st.integers(0, 2 ** 16))
def test_columns_give_one_whole_calls_bits(count, seed):
    """`evaluate_columns` (maps as wide as the next power of two, padded) on columns."""
    function = node_function()
    x, theta = draw(count, seed)[0][0], draw(count, seed)[1]
    symbols = function.mx_in()
    single = ca.Function("first", symbols, [function.call(symbols)[0]])
    owner = type("Owner", (), {})()  # the cache holds its maps per owner (weakly)
    y = np.random.default_rng(seed + 1).uniform(-2, 2, (1, count))
    got = evaluate_columns(owner, single, [x.T, y], theta)
    expected = single.map(count)(x.T, y, np.tile(theta[:, None], count)).full()
    assert got.flags.c_contiguous
    assert np.array_equal(got, expected)
