"""Why shooting found no continuous solution, in words that match the cause: a flow that
escapes to infinity is an escape, not a conjugate point (issue 45: a fixed-endpoint problem
whose exact flow escaped, q = nan, was blamed on a conjugate point)."""

import numpy as np

from ddvp_nlp import HamiltonianSystem
from ddvp_nlp.solvers.exact.flow import exact_flow
from ddvp_nlp.solvers.exact.shooting import _none


def test_an_escaping_flow_is_named_an_escape():
    # H = p^2/2 - q^4 from q = 1, p = 2: q' = p, p' = 4 q^3 blows up in finite time (< 1)
    system = HamiltonianSystem(lambda q, p, t: p[0] ** 2 / 2 - q[0] ** 4, 1, name="blowup")
    t = np.linspace(0.0, 3.0, 7)
    z = np.zeros((7, 2))
    z[0] = [1.0, 2.0]
    huge = [np.full((2, 2), 1e300)] * 6  # what the segments' tangents look like by then
    shot = _none(system, np.zeros(0), t, z, np.array([1.5]), 6, 3, 1.0, huge,
                 exact_flow(system), 1e-12, scale=np.ones(2))
    assert "escapes" in shot.reason and "conjugate" not in shot.reason
    assert shot.trajectory is None and shot.p0 is None
