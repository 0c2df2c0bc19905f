"""A fixed-endpoint problem: the pendulum from q = 0.5 to q = -0.036 in 9 time units.

All node times, positions and momenta are solved at once (docs/theory.md section 6).
Run: python examples/fixed_endpoint.py
"""

from ddvp_nlp import load_scene, solve_bvp

system = load_scene("pendulum").system
solution = solve_bvp(system, [0.5], [-0.036], (0.0, 9.0), nodes=181, scheme="vddvp")

print(solution)
changes = solution.ends.p_sign_changes  # which of several solutions this is
print(f"p(0) = {solution.p[0, 0]:.6f}, sign changes of p per component {changes}")
print(f"steps from {solution.tau.min():.4f} to {solution.tau.max():.4f}")
