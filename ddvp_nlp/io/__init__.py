"""Input and output of the workbench: file formats and figures, nothing else.

Every file a command writes goes through one output layer (``atomic.py``: folders opened
without following links, one writer at a time, files written whole and renamed into place, a
manifest of checksums written last); the formats of a run's folder, an orbit's, a section's;
every figure drawn by matplotlib under one house style (``figures.py``), imported only when a
figure is drawn. Studies decide what to write; io says how. The module map is in
``docs/architecture.md``.

Rules: io imports the library's public names and ``scenes``; never ``runner``, ``studies`` or
``cli``.
"""

from typing import TYPE_CHECKING

from ..cache import lazy_exports

# name -> module (relative to this package) that defines it: the names scripts and users take
# from io (tests/architecture/test_architecture.py holds the scripts to them)
PUBLIC = {
    # the house style of every figure: draw inside styled(), on new_figure(), write with save()
    "styled": "figures", "new_figure": "figures", "save": "figures",
    # run folders
    "read_run": "run_folder", "write_run": "run_folder", "run_energies": "run_folder",
    "plot_solution": "run_figure", "plot_trajectory": "run_figure",
    # any set of files written whole, read back checked
    "output_folder": "atomic", "read_set": "atomic",
    # periodic orbits, families, sections
    "plot_orbit": "orbit_files", "write_family": "orbit_files",
    "plot_followed_family": "orbit_figures", "write_section": "section_files",
    # the comparison figures
    "plot_work_precision": "work_precision_figure", "plot_horizons": "horizons_figure",
    "plot_growth": "horizons_figure",
    # the machine and date every timing of a report stands beside; a Markdown table that renders
    "machine": "markdown", "markdown_table": "markdown",
}

if TYPE_CHECKING:  # for readers and static tools; loaded on first use below
    from .atomic import output_folder, read_set
    from .figures import new_figure, save, styled
    from .horizons_figure import plot_growth, plot_horizons
    from .markdown import machine, markdown_table
    from .orbit_figures import plot_followed_family
    from .orbit_files import plot_orbit, write_family
    from .run_figure import plot_solution, plot_trajectory
    from .run_folder import read_run, run_energies, write_run
    from .section_files import write_section
    from .work_precision_figure import plot_work_precision

__getattr__, __dir__ = lazy_exports(__name__, PUBLIC)

__all__ = ["machine", "markdown_table", "new_figure", "output_folder", "plot_followed_family",
           "plot_growth", "plot_horizons", "plot_orbit", "plot_solution", "plot_trajectory",
           "plot_work_precision", "read_run", "read_set", "run_energies", "save", "styled",
           "write_family", "write_run", "write_section"]
