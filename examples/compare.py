"""Three energy rules on the harmonic oscillator, against its exact solution.

On this oscillator the site-density weight f' H_zz f = p^2 + q^2 is constant along the orbit, so
the energy rules choose uniform steps and all three rules give the same nodes (docs/theory.md
section 7); change the scene to "kepler" to see them part.

The full work-precision study (every method, error against run time) is `ddvp compare SCENE`.
Run: python examples/compare.py
"""

import time

import numpy as np

from ddvp_nlp import load_scene, march

scene = load_scene("harmonic")
config = scene.resolve()
for scheme in ("vddvp", "lee", "fixed"):
    started = time.perf_counter()
    solution = march(
        scene.system,
        config.q0,
        config.p0,
        (0.0, config.t_end),
        tau0=0.05,
        params=config.params,
        scheme=scheme,
    )
    seconds = time.perf_counter() - started
    q_exact, p_exact = scene.exact(solution.t, config.q0, config.p0, config.t0,
                                   *config.params.values())
    error = np.max(np.abs(np.hstack([solution.q - q_exact, solution.p - p_exact])))
    energy = solution.energy(scene.system)
    print(f"{scheme:6s} {solution.steps:4d} steps, error {error:.2e}, "
          f"energy drift {abs(energy - energy[0]).max():.1e}, {seconds:.3f} s")
