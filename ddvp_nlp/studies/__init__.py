"""Studies: many runs and what they measure (work-precision, horizons, stress cases, sweeps,
the paper's claims, Poincare sections, the verdict study). Each study is a plan (its inputs
checked, its tasks listed, before anything runs), a run (the tasks, through ``runner``) and a
report (its files, written through ``io``). The module map is in ``docs/architecture.md``.

Rules: a study imports the library's public names, ``scenes``, ``io`` and ``runner``; never
``cli``.
"""
