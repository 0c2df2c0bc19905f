"""Circular restricted three-body problem in the rotating frame, spatial (Earth-Moon by default).

Units: the primaries' distance, their total mass and ``1/n`` (``n`` their mean motion) are 1; the
Earth (mass ``1 - mu``) sits at ``(-mu, 0, 0)``, the Moon (``mu``) at ``(1 - mu, 0, 0)``. With the
canonical momenta ``p = v + omega x q`` (``omega = e_z``)::

    H = |p|^2 / 2 + y p_x - x p_y - (1 - mu) / r_1 - mu / r_2,
    r_1 = |q - (-mu, 0, 0)|,  r_2 = |q - (1 - mu, 0, 0)|,

not separable (the Coriolis terms ``y p_x - x p_y``); ``H = -C/2`` with ``C`` the Jacobi constant.
``mu = 0.01215058560962404`` (Earth-Moon, as in JPL's three-body orbit catalogue).

Periodic orbits (``ddvp periodic cr3bp``): the planar Lyapunov family about L1, on the section
``y = 0`` (node 0 crossing it towards ``+y``, on the Earth's side of L1). The default start is
the linearised Lyapunov orbit at the prescribed energy (``lyapunov_guess``): the march from the
section's point needs a ray from the origin through the orbit, which the Earth at the origin
spoils. The family loses its in-plane centre at small amplitude already (L1 is a saddle in the
plane: every Lyapunov orbit has one real pair), and its vertical pair crosses +1 at the halo
family's birth (``docs/periodic/bifurcations.md``).
"""

import casadi as ca
import numpy as np

from ddvp_nlp import PeriodicSettings, Scene

EARTH_MOON = 0.01215058560962404


def _root(f, a, b):
    """The root of ``f`` in ``[a, b]`` (``f(a) < 0 < f(b)``) by bisection to the last bit: the
    scene's two roots are of monotone functions, and bisection keeps scipy out of the file's
    loading (``ddvp scenes`` loads every scene; scipy.optimize's import was 0.4 s of it)."""
    while True:
        middle = 0.5 * (a + b)
        if middle in (a, b):
            return middle
        a, b = (middle, b) if f(middle) < 0 else (a, middle)


def hamiltonian(q, p, t, mu):
    x, y, z = q[0], q[1], q[2]
    r1 = ca.sqrt((x + mu) ** 2 + y ** 2 + z ** 2)
    r2 = ca.sqrt((x - 1 + mu) ** 2 + y ** 2 + z ** 2)
    return ca.sumsqr(p) / 2 + y * p[0] - x * p[1] - (1 - mu) / r1 - mu / r2


def energy(q, p, mu):
    """``H`` at rows of ``q``, ``p`` (numpy)."""
    q, p = np.atleast_2d(q), np.atleast_2d(p)
    x, y, z = q[:, 0], q[:, 1], q[:, 2]
    r1 = np.sqrt((x + mu) ** 2 + y ** 2 + z ** 2)
    r2 = np.sqrt((x - 1 + mu) ** 2 + y ** 2 + z ** 2)
    return (np.sum(p ** 2, axis=1) / 2 + y * p[:, 0] - x * p[:, 1] - (1 - mu) / r1 - mu / r2)


def lagrange_point_l1(mu=EARTH_MOON) -> float:
    """``x`` of L1, the root of ``dOmega/dx = 0`` between the primaries."""
    def slope(x):
        return x - (1 - mu) * (x + mu) / abs(x + mu) ** 3 - mu * (x - 1 + mu) / abs(x - 1 + mu) ** 3
    return _root(slope, -mu + 1e-3, 1 - mu - 1e-3)


def l1_frequencies(mu=EARTH_MOON):
    """``(x_L1, c_2, omega_p, omega_v, kappa)``: the planar and vertical frequencies of the
    linearisation at L1 (``c_2 = (1 - mu)/r_1^3 + mu/r_2^3``) and the in-plane amplitude ratio
    ``kappa`` of ``xi = -A cos(omega_p t)``, ``eta = kappa A sin(omega_p t)``."""
    x = lagrange_point_l1(mu)
    c2 = (1 - mu) / abs(x + mu) ** 3 + mu / abs(x - 1 + mu) ** 3
    omega_p = np.sqrt((2 - c2 + np.sqrt(9 * c2 ** 2 - 8 * c2)) / 2)
    kappa = (omega_p ** 2 + 1 + 2 * c2) / (2 * omega_p)
    return x, c2, omega_p, np.sqrt(c2), kappa


def linear_lyapunov(amplitude, mu=EARTH_MOON, samples=401):
    """``(t, q, p)`` of the linearised planar Lyapunov orbit of ``x``-amplitude ``amplitude``
    over one period ``2 pi / omega_p``, from ``y = 0`` on the Earth's side moving towards
    ``+y``."""
    x_l1, _, omega, _, kappa = l1_frequencies(mu)
    t = np.linspace(0.0, 2 * np.pi / omega, samples)
    xi, eta = -amplitude * np.cos(omega * t), kappa * amplitude * np.sin(omega * t)
    xi_dot, eta_dot = amplitude * omega * np.sin(omega * t), kappa * amplitude * omega * np.cos(
        omega * t)
    x, y = x_l1 + xi, eta
    q = np.column_stack([x, y, np.zeros_like(t)])
    p = np.column_stack([xi_dot - y, eta_dot + x, np.zeros_like(t)])
    return t, q, p


def lyapunov_guess(energy_level, mu=EARTH_MOON):
    """The linearised Lyapunov orbit whose start has ``H = energy_level`` (``{"t", "q", "p"}``);
    ``ValueError`` below L1's energy or beyond the amplitude 0.2."""
    def excess(amplitude):
        _, q, p = linear_lyapunov(amplitude, mu, samples=2)
        return float(energy(q[:1], p[:1], mu)[0]) - energy_level
    if excess(0.0) >= 0 or excess(0.2) <= 0:
        raise ValueError(f"energy {energy_level!r} is not that of a linearised L1 Lyapunov orbit "
                         f"of amplitude 0 .. 0.2 (H from {excess(0.0) + energy_level:.8g} to "
                         f"{excess(0.2) + energy_level:.8g})")
    t, q, p = linear_lyapunov(_root(excess, 0.0, 0.2), mu)
    return {"t": t, "q": q, "p": p}


_t, _q, _p = linear_lyapunov(0.01)
q0, p0 = _q[0], _p[0]
# The default march: one period of the small Lyapunov orbit (it leaves it within a few
# periods: the orbit's multiplier is about 2000).
scene = Scene(hamiltonian, n=3, params={"mu": EARTH_MOON}, q0=q0, p0=p0, tau0=0.01,
              t_end=float(_t[-1]),
              periodic=PeriodicSettings(section="q2=0", energy=-1.5935, nodes=201,
                                        guess=lyapunov_guess))
