"""The reasons a test may be slow (tests/README.md): the root conftest.py refuses a mark without
one of them, and tests/architecture/ checks every mark in the files. Here, not in conftest.py,
because ``from conftest import ...`` finds whichever conftest module was loaded last (a
folder's own conftest.py shadowed the root's)."""

SLOW_REASONS = {
    "study": "a long study that measures a claim (orders, families, random systems)",
    "repetition": "a costly repetition of a property a cheaper case of the default run checks",
    "processes": "starts processes, clusters or file-system faults: seconds each",
}
