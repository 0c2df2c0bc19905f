"""A start about an equilibrium: the linearised periodic orbit of a centre mode at a prescribed
energy (`linearised_orbit`), a ``guess`` for `solve_periodic` and the families.

At an equilibrium ``z_e`` (``J grad H(z_e) = 0``) the flow's linearisation is ``A = J Hess H``.
A centre pair ``+-i omega`` with eigenvector ``v`` (``A v = i omega v``) spans the orbits
``z(t) = z_e + a Re(e^(i omega (t - t_0)) v)``, of period ``2 pi / omega``, on which ``H - H(z_e)``
is ``a^2`` times the quadratic form ``h = m^T Hess m / 2`` (``m = z(t_0) - z_e`` per unit
amplitude; the same at every phase) to second order. The mode is
the centre pair whose eigenvector moves the section's coordinate the most (the Lyapunov orbits
about a collinear libration point cross ``y = 0``; the vertical mode of a spatial problem does
not). The phase puts node 0 on the section, the section's coordinate increasing; the amplitude
``a`` makes ``H(z(0)) = E``: ``sqrt((E - H(z_e)) / h)`` corrected by the secant method on the
full ``H`` (the linearised orbit is not on one level of ``H``: node 0 carries the energy, as the
grid's first interval does).

Errors name the argument: an equilibrium that is not one (a rate of ``J grad H`` above ``1e-8``
of what ``|A|`` makes of the point's magnitudes or the orbit's reach, in each coordinate's
units), a section that does not pass through it (by ``1e-8`` of the same), no centre pair, or
an energy on the side of ``H(z_e)`` the mode does not reach.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...cache import cached
from ...errors import InputError
from ...validation import check_real, check_state
from .orbit import parse_section

# Samples of the linearised period in the guess (solve_periodic resamples it on its grid).
SAMPLES = 401
# An equilibrium is one when its rates are below this fraction of what the linearised flow makes
# of the point's magnitudes or the orbit's reach, and on the section when its distance is.
AT_REST = 1e-8
# An eigenvalue is a centre's when its real part is below this fraction of its modulus.
CENTRE_TOL = 1e-8
# Secant steps on the amplitude, and their tolerance on H relative to |E - H(z_e)| (|E| where
# that is below E's own round-off).
AMPLITUDE_STEPS = 40
AMPLITUDE_TOL = 1e-13


def equilibrium_derivatives(system) -> ca.Function:
    """``(z, theta) -> (H, grad H, Hess H)`` (also the search's Newton on ``grad H = 0``)."""
    def build():
        z = ca.vertcat(system.q, system.p)
        hessian, gradient = ca.hessian(system.H, z)
        return ca.Function("equilibrium_derivatives", [z, system.theta],
                           [system.H, gradient, hessian])
    return cached(system, ("equilibrium_derivatives",), build)


def linearised_orbit(system, *, energy: float, equilibrium, section="p1=0", params=None,
                     samples: int = SAMPLES) -> dict:
    """One period of the linearised orbit about ``equilibrium`` at ``energy`` (module
    docstring), as ``{"t", "q", "p"}``: a ``guess`` for `solve_periodic`,
    `follow_periodic_family` and a scene's ``PeriodicSettings(guess=...)``.

    Args:
        system: an autonomous Hamiltonian system.
        energy: the energy of the orbit's node 0.
        equilibrium: ``z_e = (q, p)``, ``2n`` numbers, where ``J grad H = 0``.
        section: the section of the solve (``"q2=0"``): it must pass through the equilibrium.
        params: the system's parameter values.
        samples: points of the period in the guess (at least 4).

    Returns:
        ``{"t", "q", "p"}`` of ``samples`` rows over one linearised period, the last the first.
    """
    energy = check_real("energy", energy)
    if not isinstance(samples, (int, np.integer)) or isinstance(samples, bool) or samples < 4:
        raise InputError(f"samples must be an integer >= 4, got {samples!r}")
    n = system.n
    z_e = np.asarray(check_state("equilibrium", equilibrium, 2 * n), float)
    index, value, label = parse_section(section, n)
    if index == 0:
        raise InputError(f"section: a linearised orbit needs a section on q or p, got {label!r}")
    theta = np.asarray(system.parameter_vector(params), float)
    H_e, gradient, hessian = (np.asarray(x, float)
                              for x in equilibrium_derivatives(system)(z_e, theta))
    H_e = float(H_e.ravel()[0])
    J = np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])
    field = J @ gradient.ravel()
    if not (np.all(np.isfinite(field)) and np.all(np.isfinite(hessian))):
        raise InputError(f"equilibrium: H's derivatives at {z_e.tolist()} are not finite: give "
                         "a point where the flow is at rest")
    omega, v = _centre_mode(J @ hessian, index, z_e)
    # phase: node 0 on the section, its coordinate |v_s| omega sin(omega t) there: increasing
    phase = np.angle(v[index - 1]) + np.pi / 2
    mode = np.real(np.exp(-1j * phase) * v)     # z(0) - z_e per unit amplitude
    form = 0.5 * float(mode @ hessian @ mode)   # H - H(z_e) per unit amplitude squared
    amplitude = _amplitude(system, theta, z_e, mode, energy, H_e, form, omega)
    # at rest beside the flow on the point's magnitudes or the orbit's reach, whichever is
    # larger, in each coordinate's units (max(1, |z_e|) and max(1, |Hess H|) judged the same
    # point by its units; the reach lets an equilibrium at the origin be given to round-off)
    reach = np.maximum(np.abs(z_e), amplitude * np.abs(v))
    if not np.all(np.abs(field) <= AT_REST * (np.abs(J @ hessian) @ reach)):
        raise InputError(f"equilibrium: J grad H = {field.tolist()} at {z_e.tolist()}, not zero: "
                         "give a point where the flow is at rest")
    if abs(z_e[index - 1] - value) > AT_REST * max(abs(z_e[index - 1]), abs(value),
                                                   reach[index - 1]):
        raise InputError(f"section {label!r} does not pass through the equilibrium (its "
                         f"coordinate there is {z_e[index - 1]!r}): use a section through it")
    t = np.linspace(0.0, 2 * np.pi / omega, samples)
    states = z_e + amplitude * np.real(np.exp(1j * (omega * t[:, None] - phase)) * v[None, :])
    states[0, index - 1] = value  # node 0 on the section, whatever the amplitude's round-off
    states[-1] = states[0]
    return {"t": t, "q": states[:, :n].copy(), "p": states[:, n:].copy()}


def _centre_mode(A: np.ndarray, index: int, z_e: np.ndarray):
    """``(omega, v)`` of the centre pair (``omega > 0``) whose eigenvector moves coordinate
    ``index - 1`` the most, ``v`` scaled to unit length."""
    values, vectors = np.linalg.eig(A)
    scale = max(float(np.max(np.abs(values))), 1e-300)
    centre = [j for j in range(values.size) if values[j].imag > 0
              and abs(values[j].real) <= CENTRE_TOL * abs(values[j]) + 1e-12 * scale]
    if not centre:
        raise InputError(f"equilibrium {z_e.tolist()}: its linearisation has no centre pair "
                         f"(eigenvalues {np.round(values, 8).tolist()}), so no small periodic "
                         "orbit is about it")
    weights = [abs(vectors[index - 1, j]) / np.linalg.norm(vectors[:, j]) for j in centre]
    best = centre[int(np.argmax(weights))]
    if max(weights) <= 1e-8:
        raise InputError("section: no centre mode of the equilibrium crosses it (their "
                         "eigenvectors leave its coordinate at rest); use another section")
    v = vectors[:, best] / np.linalg.norm(vectors[:, best])
    return float(values[best].imag), v


def _amplitude(system, theta, z_e, mode, energy: float, H_e: float, form: float,
               omega: float) -> float:
    """The amplitude whose node 0 ``z_e + a mode`` has ``H = energy``: the quadratic estimate,
    then secant steps on the full ``H``."""
    if form == 0 or (energy - H_e) / form <= 0:
        side = "above" if form > 0 else "below"
        raise InputError(f"energy {energy!r}: the centre mode of frequency {omega:.6g} about "
                         f"the equilibrium (H = {H_e:.10g}) reaches only energies {side} it")
    n = system.n

    def excess(a):
        z = z_e + a * mode
        return float(system.energy(z[None, :n], z[None, n:], [0.0], theta)[0]) - energy
    a0 = float(np.sqrt((energy - H_e) / form))
    a1 = 1.01 * a0
    f0, f1 = excess(a0), excess(a1)
    above = abs(energy - H_e)  # the mode's energy: in H's units, blind to a constant in H
    for _ in range(AMPLITUDE_STEPS):
        if not np.isfinite(f1) or abs(f1) <= AMPLITUDE_TOL * max(above, abs(energy)) \
                or f1 == f0:
            break
        a0, a1, f0 = a1, a1 - f1 * (a1 - a0) / (f1 - f0), f1
        f1 = excess(a1)
    if np.isfinite(f1) and a1 > 0 and abs(f1) <= 1e-6 * above:
        return a1
    return float(np.sqrt((energy - H_e) / form))  # the quadratic estimate: a start only
