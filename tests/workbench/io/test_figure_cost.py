"""What a figure costs, counted in what it draws and what it imports, never in seconds: a long
run's figure draws as many points as its panels have pixels, not as many as the run has
nodes; the figure's matplotlib import leaves out only help text, and only in the command's
own process."""

from __future__ import annotations

import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from ddvp_nlp.io import figures
from ddvp_nlp.io import run_figure as plotting
from ddvp_nlp.solution import Solution, Status
from ddvp_nlp.startup import started_as_command


def long_run(nodes: int) -> Solution:
    """A run of ``nodes`` nodes with the shape of a slowly modulated pendulum (drawing counts
    points, so the nodes need not solve anything)."""
    t = np.linspace(0.0, 0.5 * (nodes - 1), nodes)
    q = (0.7 + 0.005 * np.sin(1e-3 * t)) * np.cos(t)
    p = -0.7 * np.sin(t)
    rng = np.random.default_rng(5)
    return Solution(t=t, q=q[:, None], p=p[:, None], status=Status.SUCCESS, message="",
                    scheme="vddvp", energy_residual=1e-16 * rng.random(nodes - 2),
                    canonical_residual=np.zeros(nodes - 1))


def points_drawn(ax) -> int:
    """The points ``ax`` hands to the renderer: the vertices of its lines and of its
    collections (a filled envelope is one polygon)."""
    return (sum(line.get_xdata().size for line in ax.lines)
            + sum(len(path.vertices) for c in ax.collections for path in c.get_paths()))


def drawn_figure(solution):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    energy = ("energy residual", [("", solution.t[1:-1], solution.energy_residual)])
    with figures.styled():
        fig = plotting._figure(solution, plotting._rows(solution, True, energy), "long run")
        columns = {id(ax): figures.bins_for(ax) for ax in fig.axes}
        FigureCanvasAgg(fig).draw()
    return fig, columns


def test_a_long_run_draws_a_few_points_per_pixel_whatever_its_length():
    dots = {}
    for nodes in (plotting.THIN_FROM_NODES, 4 * plotting.THIN_FROM_NODES):
        solution = long_run(nodes)
        fig, columns = drawn_figure(solution)
        time_panels = [ax for ax in fig.axes if ax.get_xlabel() == "$t$" or not ax.get_xlabel()]
        assert len(time_panels) == 8  # q, p, steps, energy; whole run and its first steps
        for ax in time_panels:
            # the envelope: the minimum and the maximum of each pixel column, as two lines and
            # the polygon between them
            assert points_drawn(ax) <= 4 * columns[id(ax)] + 8, ax.get_ylabel()
        phase = next(ax for ax in fig.axes if ax.get_title() == "phase portrait")
        shown = next(line for line in phase.lines if line.get_marker() == ",").get_xydata()
        dots[nodes] = len(shown)
        # the axes' limits are the whole cloud's: its extreme nodes are among those drawn
        q, p = solution.q[:, 0], solution.p[:, 0]
        assert (shown[:, 0].min(), shown[:, 0].max()) == (q.min(), q.max())
        assert (shown[:, 1].min(), shown[:, 1].max()) == (p.min(), p.max())
    # one node per occupied half pixel of the phase portrait: four times the nodes on the same
    # band light the same pixels and draw about as many dots
    few, many = dots.values()
    assert few < plotting.THIN_FROM_NODES / 4 and many < 1.25 * few


def test_a_run_below_the_thinning_threshold_draws_every_node():
    solution = long_run(plotting.THIN_FROM_NODES - 1)
    fig, _ = drawn_figure(solution)
    phase = next(ax for ax in fig.axes if ax.get_title() == "phase portrait")
    dots = next(line for line in phase.lines if line.get_marker() == ",")
    assert dots.get_xdata().size == solution.t.size


@pytest.mark.parametrize("nodes", [400, 50_000])
def test_a_higher_order_run_draws_its_nodes_or_their_envelope(nodes):
    solution = long_run(nodes)
    scene = SimpleNamespace(name="long", order=2)
    keep = figures.Keep()
    plotting.plot_higher_trajectory(solution, scene, "march", solution.q,
                                    np.sin(solution.t[1:-1]), keep)
    pixels = figures.TEXT_WIDTH * 0.75 * 200  # the figure's width in pixel columns
    for ax in keep.figure.axes:
        if nodes < pixels:  # every node drawn, as a dot
            assert any(line.get_marker() == "." and line.get_xdata().size >= nodes - 2
                       for line in ax.lines), ax.get_ylabel()
        else:
            assert points_drawn(ax) <= 6 * pixels, ax.get_ylabel()


@pytest.mark.parametrize("seed", range(4))
def test_thinning_keeps_one_point_per_occupied_cell_and_the_extremes(seed):
    rng = np.random.default_rng(seed)
    n, cells = 20_000, int(rng.integers(8, 60))
    x = rng.standard_normal(n) * rng.uniform(1e-3, 1e3)
    y = rng.standard_t(3, n) + rng.uniform(-1e6, 1e6)
    x[rng.integers(0, n, 5)] = np.nan
    kept = figures.thin_points(x, y, cells)
    assert np.all(np.diff(kept) > 0) and np.all(np.isfinite(x[kept]) & np.isfinite(y[kept]))

    def cell(index):
        finite = np.isfinite(x) & np.isfinite(y)
        ix = [np.minimum(((v[index] - v[finite].min()) / np.ptp(v[finite]) * cells)
                         .astype(int), cells - 1) for v in (x, y)]
        return ix[0] * cells + ix[1]

    finite = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    # every occupied cell keeps a point, and only the extremes share a cell with another
    assert set(cell(kept)) == set(cell(finite))
    assert len(kept) - len(set(cell(kept))) <= 4
    for values in (x, y):
        assert np.nanmin(values) in values[kept] and np.nanmax(values) in values[kept]


def test_the_bins_follow_the_resolution_the_figure_is_saved_at():
    import matplotlib

    with figures.styled():
        fig = figures.new_figure(4.0, 2.0, layout=None)
        ax = fig.add_axes([0.1, 0.1, 0.8, 0.8])
        assert figures.bins_for(ax) == int(0.8 * 4.0 * 200)  # the style's savefig.dpi
        with matplotlib.rc_context({"savefig.dpi": 100}):
            assert figures.bins_for(ax) == int(0.8 * 4.0 * 100)


def matplotlib_help(help_tables: str) -> list[str]:
    """In a fresh process: load matplotlib for a figure (``help_tables`` as given, or the
    default), then report whether ``Line2D.set`` and ``Axes.plot`` list the settable
    properties, and whether ``kwdoc`` answers as matplotlib's own afterwards."""
    code = (
        "from ddvp_nlp.io import figures\n"
        f"figures.load_matplotlib({help_tables})\n"
        "import matplotlib.artist, matplotlib.axes, matplotlib.lines\n"
        "print('antialiased' in matplotlib.lines.Line2D.set.__doc__,\n"
        "      'antialiased' in matplotlib.axes.Axes.plot.__doc__,\n"
        "      'antialiased' in matplotlib.artist.kwdoc(matplotlib.lines.Line2D))\n"
        # what the import left out is matplotlib's own again afterwards: a class made now gets
        # its set's signature, and the 3-D toolkit imports
        "class Later(matplotlib.lines.Line2D): pass\n"
        "import inspect, mpl_toolkits.mplot3d\n"
        "print('antialiased' in inspect.signature(Later.set).parameters,\n"
        "      mpl_toolkits.mplot3d.Axes3D is not None)\n")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                         text=True).stdout
    return out.split()


# Each case is a fresh process that loads matplotlib (a second of CPU). Asking for the tables
# is the default's repetition (slow tier): the default case keeps them, the False case shows
# what leaving them out leaves out.
@pytest.mark.slow_when(lambda help_tables, **_: help_tables == "help_tables=True",
                       why="repetition")
@pytest.mark.parametrize("help_tables, answers", [
    ("", ["True"] * 5),  # pytest is not the ddvp command: the default keeps them
    ("help_tables=True", ["True"] * 5),
    # without the tables, matplotlib's kwdoc is its own again once the import is done
    ("help_tables=False", ["False", "False", "True", "True", "True"]),
], ids=["default", "asked-for", "left-out"])
def test_the_figure_import_leaves_out_only_help_text_and_only_when_asked(help_tables, answers):
    assert not started_as_command()
    assert matplotlib_help(help_tables) == answers
