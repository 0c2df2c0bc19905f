"""The state at any time of a march, and exactly at t_end (docs/theory.md section 10).

A march ends at the first node past t_end; Solution.at interpolates between the nodes by cubic
Hermite polynomials with the vector field at the nodes, with the scheme's own order of error.
Run: python examples/dense_output.py
"""

import numpy as np

from ddvp_nlp import load_scene, march

scene = load_scene("harmonic")
solution = march(scene.system, [1.0], [0.0], (0.0, 10.0), tau0=0.07)
print(f"last node t = {solution.t[-1]:.4f}, asked for t_end = {solution.t_end}")

q_end, p_end = solution.at_end()
q_exact, p_exact = scene.exact(np.array([10.0]), np.array([1.0]), np.array([0.0]), 0.0, 1.0)
print(f"at t_end: q = {q_end[0]:.6f} (exact {q_exact[0, 0]:.6f}), "
      f"p = {p_end[0]:.6f} (exact {p_exact[0, 0]:.6f})")

times = np.linspace(0.0, 10.0, 1001)  # a uniform grid for plotting or comparison
q, p = solution.at(times)
q_exact, p_exact = scene.exact(times, np.array([1.0]), np.array([0.0]), 0.0, 1.0)
print(f"largest error on 1001 uniform times: {np.max(np.abs(q - q_exact)):.2e}")
