"""Fit a model to noisy samples of one orbit with the march's exact derivatives.

A pendulum's frequency w, and a Kepler problem's mu, are recovered with the initial state from
noisy positions sampled along one orbit: scipy.optimize.least_squares with the Jacobian
d q(t_i) / d(q0, p0, params) that march(..., derivatives=...) returns (step lengths included),
no finite differences.
Run: python examples/fit_parameters.py
"""

import casadi as ca
import numpy as np
from scipy.optimize import least_squares

from ddvp_nlp import HamiltonianSystem, Output, march


def pendulum_H(q, p, t, w):
    return p[0] ** 2 / 2 + w ** 2 * (1 - ca.cos(q[0]))


def kepler_H(q, p, t, mu):
    return (p[0] ** 2 + p[1] ** 2) / 2 - mu / ca.sqrt(q[0] ** 2 + q[1] ** 2)


def fit(system, ts, observed, guess, tau0):
    """Least squares on (q0, p0, params): residuals the marched positions at ts minus the
    observations, Jacobian the march's derivatives."""
    n = system.n
    names = list(system.params)

    def run(x):
        return march(system, x[:n], x[n:2 * n], (0.0, ts[-1]), tau0=tau0,
                     params=dict(zip(names, x[2 * n:], strict=True)), output=Output(t_eval=ts),
                     derivatives=("q0", "p0", "params"))

    def residuals(x):
        return (run(x).z_eval[:, :n] - observed).ravel()

    def jacobian(x):
        d = run(x).derivatives
        columns = np.concatenate([d["q0"], d["p0"], d["params"]], axis=2)  # (M, 2n, 2n + m)
        return columns[:, :n, :].reshape(-1, columns.shape[2])

    return least_squares(residuals, guess, jac=jacobian, x_scale="jac")


def recover(label, system, truth, guess, t_end, samples, noise, tau0, seed):
    n = system.n
    rng = np.random.default_rng(seed)
    ts = np.linspace(0.0, t_end, samples + 1)[1:]
    names = list(system.params)
    exact = march(system, truth[:n], truth[n:2 * n], (0.0, t_end), tau0=tau0 / 4,
                  params=dict(zip(names, truth[2 * n:], strict=True)), output=Output(t_eval=ts))
    observed = exact.z_eval[:, :n] + noise * rng.standard_normal((ts.size, n))
    result = fit(system, ts, observed, np.asarray(guess, float), tau0)
    # the parameters' standard errors from the Jacobian at the fit
    J = result.jac
    sigma = noise * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    for k, name in enumerate(names):
        i = 2 * n + k
        print(f"{label}: {name} = {result.x[i]:.6f} +- {sigma[i]:.1e} (true {truth[i]}), "
              f"{result.nfev} solves, {result.njev} Jacobians, cost {result.cost:.3e}")
    return result


pendulum = HamiltonianSystem(pendulum_H, 1, {"w": 1.0}, name="pendulum_w")
recover("pendulum", pendulum, truth=[1.0, 0.0, 1.3], guess=[0.8, 0.2, 1.0], t_end=10.0,
        samples=40, noise=1e-3, tau0=0.02, seed=1)

kepler = HamiltonianSystem(kepler_H, 2, {"mu": 1.0}, name="kepler_mu")
recover("kepler", kepler, truth=[1.0, 0.0, 0.0, 1.4, 1.5], guess=[0.95, 0.05, 0.05, 1.3, 1.2],
        t_end=6.0, samples=60, noise=1e-3, tau0=0.01, seed=2)
