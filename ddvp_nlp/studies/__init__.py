"""Studies: many runs and what they measure. They compute and return data objects; the files
(CSV tables' final form, figures, Markdown) are written by ``io``.

- ``methods.py``: the registry of every integrator the studies run, with its traits.
- ``reference.py``: what a study needs of a scene, and the reference solution errors are
  measured against.
- ``compare.py``: work-precision (error against run time) on one scene, and its rankings.
- ``stress.py``: stiff and extreme cases, predicted breakdowns beside observed ones.
- ``sweep.py``: a user's own grid of runs, as stress cases.
- ``poincare.py``: Poincare sections at a fixed energy (starts on the section, one ensemble,
  crossings on the dense output).
- ``paper.py``: measurements of the paper's claims.
- ``grid.py``: running grids of independent tasks, here, on local workers or on Dask; a grid's
  rows go to its result file as they finish (that is how resume works).

May import: ``solvers``, ``discrete``, ``physics``, ``scenes``, ``solution``, ``errors``,
``validation``, and ``io.row_file`` (only ``grid.py``, for the result file it resumes from).
"""
