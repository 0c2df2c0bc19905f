"""Hypothesis strategies for the accuracy tests: random systems (``studies.verdicts``), their
starts, steps, schemes and the units they are marched in."""

from hypothesis import strategies as st

from ddvp_nlp.studies.verdict_study import DrawnCase, RandomSystem, Units


@st.composite
def systems(draw):
    n = draw(st.integers(1, 3))
    pairs = n * (n - 1) // 2
    positive = st.floats(0.2, 3.0)

    def vector(size, strategy):
        return tuple(draw(st.lists(strategy, min_size=size, max_size=size)))

    invariant = n >= 2 and draw(st.booleans())
    return RandomSystem(
        n=n, potential=draw(st.sampled_from(["polynomial", "trigonometric"])),
        stiffness=vector(n, positive), cubic=vector(n, st.floats(-0.5, 0.5)),
        quartic=vector(n, st.floats(0.05, 1.0)), coupling=vector(pairs, st.floats(0.1, 1.0)),
        masses=vector(n, st.floats(0.5, 2.0)), mixing=draw(st.floats(-0.3, 0.3)),
        forcing=draw(st.sampled_from([0.0, 0.3])), frequency=draw(st.floats(0.3, 3.0)),
        gauge=draw(st.sampled_from([0.0, 5.0])), translation_invariant=invariant)


@st.composite
def cases_and_units(draw):
    system = draw(systems())
    n = system.n
    amplitude = draw(st.floats(0.1, 1.5))
    start = [tuple(draw(st.lists(st.floats(-1, 1), min_size=n, max_size=n)))
             for _ in range(2)]
    case = DrawnCase(system, tuple(amplitude * v for v in start[0]),
                     tuple(amplitude * v for v in start[1]),
                     tau0=draw(st.floats(0.01, 0.8)), t_end=draw(st.floats(2.0, 12.0)),
                     scheme=draw(st.sampled_from(["vddvp", "lee", "fixed"])))
    exponent = st.floats(-4, 4)
    q, p, t = (10 ** draw(exponent) for _ in range(3))
    units = Units(q=q, p=p, t=t, offset=draw(st.floats(-1e3, 1e3)) * q * p / t,
                  shift=draw(st.floats(-1e4, 1e4)) * q if system.translation_invariant else 0.0,
                  t_shift=draw(st.floats(-1e2, 1e2)) * t)
    return case, units


@st.composite
def cases(draw):
    """A case across the range the study draws from (``studies.verdicts.draw_case``): first
    steps from 10^-2.5 to 1 of the system's own time, up to 4000 steps, random units."""
    case, units = draw(cases_and_units())
    tau0 = 10 ** draw(st.floats(-2.5, 0.0))
    t_end = min(draw(st.floats(2.0, 20.0)), 2000 * tau0)
    return DrawnCase(case.system, case.Q0, case.P0, tau0, max(t_end, tau0), case.scheme, units)


def random_pair(rng, name: str = "random_pair"):
    """A random two-degree-of-freedom system whose ``H`` depends on both of its parameters
    ``k`` and ``c`` (drawn in [0.5, 1.5)): what the derivative tests differentiate in."""
    import casadi as ca

    from ddvp_nlp import HamiltonianSystem

    k, c = 0.5 + rng.random(2)

    def H(q, p, t, k, c):
        return (p[0] ** 2 + p[1] ** 2) / 2 + k * q[0] ** 2 / 2 + c * q[0] * q[1] ** 2 \
            + ca.cos(q[1]) * k * c
    return HamiltonianSystem(H, 2, {"k": k, "c": c}, name=name)
