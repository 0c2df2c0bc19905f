"""The exact flow ``z' = f(z, t) = (H_p, -H_q)``: the one truth every verdict and every
comparison measures against. It shares nothing with the schemes it checks: no equation of
``discrete/``, no Newton of the march, no step the scheme chose other than the node times.

- ``flow.py``: the flow integrated by a compiled order-8 Runge-Kutta method with its own error
  controlled (the reference trajectory at a run's node times, the flow over each step).
- ``variational.py``: the flow with its derivatives (the variational equations): monodromy
  matrices, shooting Jacobians.
- ``shooting.py``: the continuous fixed-endpoint problem near a discrete solution, by multiple
  shooting.
- ``closure.py``: the exact periodic orbit near a discrete one, and its monodromy.
"""
