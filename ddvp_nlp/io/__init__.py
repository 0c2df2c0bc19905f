"""Input and output: run folders, figures, Markdown reports and input files.

- ``runs.py``: writing a run's ``result.npz``, ``meta.json`` and figure (every kind of scene).
- ``figures.py``: the one plotting stack: matplotlib (imported only when a figure is drawn)
  under the house style ``ddvp.mplstyle``, PNG/SVG/PDF, min/max decimation of long series.
- ``plotting.py``: the trajectory figure of a run or of any ``Solution`` (``ddvp_nlp.plot``).
- ``periodic_runs.py``: ``ddvp periodic``'s run folder (orbit and step-length figure) and a
  family's ``family.csv`` and period-against-energy figure.
- ``poincare_runs.py``: ``ddvp poincare``'s ``section.npz``, ``section.csv``, ``orbits.csv`` and
  figure.
- ``row_file.py``: a grid's CSV result file, appended row by row.
- ``markdown.py``: pieces the grid reports share (failure table, machine line).
- ``work_precision.py``: ``ddvp compare``: runs the comparison, writes its CSV, figure, summary.
- ``stress_report.py``: ``ddvp stress`` and ``ddvp sweep``: runs the grid, writes its table and
  figure.
- ``grid_file.py``: reading a sweep's TOML grid file.
- ``reproduce.py``: ``ddvp reproduce``'s figures and report, verdicts against stated thresholds.

May import everything but ``cli``; nothing but ``cli`` imports from here, except
``studies.grid``, which uses ``row_file`` (a leaf: it imports nothing of the package), and the
package root's ``plot``, which imports ``plotting`` inside the function (a facade;
docs/architecture.md).
"""
