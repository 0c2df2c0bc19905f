"""A scene's exact solution of the wrong shape (or one that fails) is refused by name with
the shape it gave, before the march (issue 45: it ended in an internal error)."""

import numpy as np
import pytest

from ddvp_nlp import InputError, Scene


def H(q, p, t):
    return (p[0] ** 2 + q[0] ** 2) / 2


def good(t, q0, p0, t0):
    s = t - t0
    return (q0 * np.cos(s) + p0 * np.sin(s))[:, None], (p0 * np.cos(s) - q0 * np.sin(s))[:, None]


@pytest.mark.parametrize("exact, words", [
    (lambda t, q0, p0, t0: (q0, p0), r"shape \(len\(t\), 1\) = \(2, 1\)"),  # ignores t
    (lambda t, q0, p0, t0: np.zeros((np.size(t), 2)), "must return \\(q, p\\)"),
    (lambda t, q0, p0, t0: (np.zeros((np.size(t), 3)), np.zeros((np.size(t), 1))), "shapes"),
    (lambda t, q0, p0, t0: 1 / 0, "ZeroDivisionError"),
])
def test_an_exact_solution_of_the_wrong_shape_is_refused_naming_the_scene(exact, words):
    scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=1.0, exact=exact, name="wrong")
    with pytest.raises(InputError, match=words) as refused:
        scene.exact_states(scene.resolve({}))
    assert "'wrong'" in str(refused.value)


def test_a_right_exact_solution_gives_rows_of_q_and_p():
    scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=1.0, exact=good, name="right")
    exact = scene.exact_states(scene.resolve({}))
    z = exact(np.array([0.0, np.pi / 2]))
    assert z == pytest.approx(np.array([[1.0, 0.0], [0.0, -1.0]]), abs=1e-12)
