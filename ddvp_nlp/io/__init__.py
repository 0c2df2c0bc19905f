"""Input and output: run folders, figures and Markdown reports.

- ``runs.py``: writing a run's ``result.npz`` and ``meta.json``.
- ``plotting.py``: the trajectory figure of a run.
- ``reproduce.py``: ``ddvp reproduce``'s figures and report.

May import everything but ``cli``; nothing but ``cli`` and ``studies`` imports from here.
"""
