"""Studies: many runs and what they measure.

- ``methods.py``: the registry of every integrator the studies run, with its traits.
- ``compare.py``: work-precision (error against run time) on one scene.
- ``stress.py``: stiff and extreme cases, predicted breakdowns beside observed ones.
- ``sweep.py``: a user's own grid of runs.
- ``paper.py``: measurements of the paper's claims.
- ``grid.py``: running grids of independent tasks, here, on local workers or on Dask.

May import: ``solvers``, ``discrete``, ``physics``, ``scenes``, ``solution``, ``errors``,
``validation``, and ``io.runs`` for the folders it resumes from.
"""
