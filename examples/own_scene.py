"""Declare your own system (a Duffing oscillator) and march it, without a scene file.

Run: python examples/own_scene.py
"""

import casadi as ca

from ddvp_nlp import Scene, march


def hamiltonian(q, p, t, k):
    # q, p: CasADi column vectors of length n; t and each parameter: scalar symbols.
    return ca.sumsqr(p) / 2 + q[0] ** 2 / 2 + k * q[0] ** 4 / 4


scene = Scene(hamiltonian, n=1, params={"k": 1.0}, q0=[1.0], p0=[0.0], tau0=0.05, t_end=20.0,
              name="duffing")
config = scene.resolve({"k": 0.5})  # override a parameter as --set k=0.5 would
solution = march(
    scene.system, config.q0, config.p0, (0.0, config.t_end), tau0=config.tau0, params=config.params
)
energy = solution.energy(scene.system)
print(solution)
print(f"H at the nodes stays within {abs(energy - energy[0]).max():.1e} of H(z_0) = {energy[0]}")
