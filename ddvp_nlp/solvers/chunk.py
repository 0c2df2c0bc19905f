"""The fast march path: many steps per call inside compiled CasADi code.

One march step (predictor, Newton on the step equations, residuals) is one CasADi ``Function``
built from the same pieces as the careful path (``march._StepFunctions``), with CasADi's
``fast_newton`` in place of ``newton`` because it can be code-generated. ``mapaccum`` repeats it
``chunk`` times per call. Where a C compiler is present the chunk is generated as C, compiled and
cached; elsewhere CasADi's virtual machine runs the same function.

``fast_newton`` never raises and never says whether it converged, so every step of a chunk is
checked afterwards by the march (finite values, ``tau > 0``, its unscaled residuals against the
tolerance, the step bounds); the first step that fails a check is redone by the careful path
from the last good state, so the fast path never changes what is accepted.

Compiled chunks are cached in ``cache_dir`` (argument, else ``$DDVP_NLP_CACHE``, else
``~/.cache/ddvp_nlp``) under a hash of the generated function, the compiler and its flags. Each
build compiles to a temporary file and renames it into place, so two processes building the same
entry at once both end with a complete library.
"""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from .compiler import cache_folder, compile_function

# error_on_fail: on the virtual machine fast_newton raises by default; compiled, it cannot.
# Either way a step that did not converge fails its residual check and is redone carefully.
FAST_NEWTON_OPTIONS = {"abstol": 1e-14, "abstolStep": 1e-14, "max_iter": 30, "error_on_fail": False}






class FastChunk:
    """``chunk`` march steps per call, compiled or on the virtual machine.

    Energy rules: state ``[t_prev, t_mid, z_prev, z_mid, drift]``; per step the outputs
    ``[t_next, z_next, canonical residual, energy residual, |z_mid|, |H_k|, H, w]``.
    Fixed rule: state ``[k, z]`` with constants ``[t0, tau, t_end, steps_total]``; outputs
    ``[t_next, z_next, canonical residual, |z_a|, H, w]``. ``H`` and the site-density weight
    ``w`` are those of the new node (energy guard, solvability monitor).

    ``compiler`` is already resolved (``find_compiler``): a path, or ``None`` for the virtual
    machine.
    """

    def __init__(self, system, scheme, functions, *, chunk: int, compiler, cache_dir):
        started = time.perf_counter()
        n2 = 2 * system.n
        theta = ca.SX.sym("theta", system.theta.numel())
        self.variable = scheme.variable_steps
        if self.variable:
            state = ca.SX.sym("state", 2 + 2 * n2 + 1)
            t_prev, t_mid = state[0], state[1]
            z_prev, z_mid = state[2:2 + n2], state[2 + n2:2 + 2 * n2]
            drift = state[-1]
            w = ca.vertcat(t_prev, t_mid, z_prev, z_mid, theta, drift)
            newton = ca.rootfinder("fast_energy_step", "fast_newton",
                                   functions.energy_residual, FAST_NEWTON_OPTIONS)
            x = newton(functions.energy_predict(w, t_mid - t_prev), w)
            canonical, energy, size, H, H_node, w_node = functions.energy_check(x, w)
            t_next = t_mid + x[-1]
            outputs = ca.vertcat(t_next, x[:-1], canonical, energy, size, H, H_node, w_node)
            step = ca.Function("step", [state, theta], [
                ca.vertcat(t_mid, t_next, z_mid, x[:-1], drift + energy), outputs])
        else:
            state = ca.SX.sym("state", 1 + n2)
            constants = ca.SX.sym("constants", 4)
            k, z_a = state[0], state[1:]
            t0, tau, t_end, total = (constants[i] for i in range(4))
            t_a = ca.if_else(k == 0, t0, t0 + k * tau)
            t_b = ca.if_else(k + 1 == total, t_end, t0 + (k + 1) * tau)
            w = ca.vertcat(t_a, t_b, z_a, theta)
            newton = ca.rootfinder("fast_fixed_step", "fast_newton", functions.fixed_residual,
                                   FAST_NEWTON_OPTIONS)
            z_b = newton(functions.fixed_predict(w), w)
            canonical, size, H_node, w_node = functions.fixed_check(z_b, w)
            step = ca.Function("step", [state, ca.vertcat(theta, constants)], [
                ca.vertcat(k + 1, z_b), ca.vertcat(t_b, z_b, canonical, size, H_node, w_node)])
        self.chunk = chunk
        function = step.mapaccum("chunk", chunk)
        self.path = "vm"
        self.compile_s = 0.0
        if compiler is not None:
            compiled_at = time.perf_counter()
            function = compile_function(function, compiler, cache_folder(cache_dir))
            self.compile_s = time.perf_counter() - compiled_at
            self.path = "compiled"
        self.function = function
        self.build_s = time.perf_counter() - started

    def __call__(self, state: np.ndarray, parameters: np.ndarray):
        """States after each step ``(chunk, size)`` and outputs ``(chunk, size)``."""
        states, outputs = self.function(state, np.tile(parameters[:, None], (1, self.chunk)))
        return np.asarray(states).T, np.asarray(outputs).T


