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
