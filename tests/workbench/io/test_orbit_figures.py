"""The followed family's stability panel: scaled to its indices, none on an edge, a log scale
where they span decades (issue 46: the CR3BP's indices 1.97 and 2648 were clipped at the top)."""

from types import SimpleNamespace as NS

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

from ddvp_nlp.io.orbit_figures import _draw_family  # noqa: E402


def _family(index_rows):
    circle = np.linspace(0.0, 2 * np.pi, 20)
    members = [NS(energy=e, orbit=NS(q=np.column_stack([np.cos(circle), np.sin(circle)]),
                                     p=np.zeros((20, 2)), steps=100, orbit=NS(period=1.0 + e)),
                  stability=NS(indices=np.asarray(k, complex), verdict="unstable",
                               trivial=np.ones(2)))
               for e, k in index_rows]
    return NS(members=members, bifurcations=[])


@pytest.mark.parametrize("rows, scale", [
    ([(0.0, [1.97, 2648.5]), (0.1, [1.99, 2600.0]), (0.2, [2.01, 2550.0])], "symlog"),
    ([(0.0, [-5.0, 1.5]), (0.1, [-6.0, 1.2])], "linear"),
    ([(0.0, [-40.0]), (0.1, [-3000.0])], "symlog")])
def test_every_index_lies_inside_the_panel(rows, scale):
    fig = Figure()
    _draw_family(fig, _family(rows))
    axes = fig.axes[2]
    low, high = axes.get_ylim()
    values = np.concatenate([np.real(k) for _, k in rows])
    assert axes.get_yscale() == scale
    assert low < min(values.min(), -2.0) and high > max(values.max(), 2.0)
    if scale == "symlog":  # a margin of a factor on the log part
        if values.max() > 3:
            assert high >= 1.5 * values.max()
        if values.min() < -3:
            assert low <= 1.5 * values.min()
