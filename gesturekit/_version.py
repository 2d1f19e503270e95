"""The version of gesturekit, recorded in every database, refiner and synthesis result it writes.

Modules read it from here rather than from the package's ``__init__``, so that
no module imports back up through the package it belongs to. It is the one place the
version is written: pyproject.toml reads it from here (``dynamic = ["version"]``), and
CHANGELOG.md's newest release names it (tests/project/test_version.py checks both).
"""

__version__ = "0.4.4"
