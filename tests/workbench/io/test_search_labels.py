"""The search figure's point labels (io/search_files.place_labels): no two labels' boxes meet
and none covers another point's marker, however close the points are (the trial's "6,7" and
"8,9" printed over each other), and each label still points at its own point."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddvp_nlp.io import figures
from ddvp_nlp.io.search_files import place_labels


def boxes(axes, notes):
    from matplotlib.text import Text

    renderer = axes.figure.canvas.get_renderer()
    for note in notes:
        note.update_positions(renderer)
    return [Text.get_window_extent(note, renderer) for note in notes]


def test_the_trials_labels_do_not_meet():
    """Pullen-Edmonds at E = 1, --max-returns 4: "8,9,10" at (1.9895, 18.6447) and "11,12" at
    (2.0104, 18.6455), one marker on the other."""
    check_labels([(1.9895377, 18.64471022), (2.0104371, 18.64550055), (2.0, 15.2)])


@pytest.mark.slow(why="repetition")
@settings(max_examples=6, derandomize=True, deadline=None, database=None)
@given(st.lists(st.tuples(st.floats(1.9, 2.1), st.floats(18.0, 19.0)), min_size=2,
                max_size=5, unique=True))
def test_labels_of_close_points_do_not_meet(points):
    check_labels(points)


def check_labels(points):
    with figures.styled():
        fig = figures.new_figure(figures.TEXT_WIDTH, 3.0)
        axes = fig.subplots()
        axes.plot(*np.array(points).T, "o", ms=4)
        axes.set_xlim(-3, 6)
        axes.set_ylim(0, 30)
        labels = [(",".join(str(2 * j + k) for k in (1, 2)), point)
                  for j, point in enumerate(points)]
        notes = place_labels(axes, labels)
        placed = boxes(axes, notes)
    assert len(notes) == len(labels)
    assert [note.xy for note in notes] == [point for _, point in labels]
    assert all(not a.overlaps(b) for i, a in enumerate(placed) for b in placed[i + 1:])
