"""The version of gesturekit, recorded in every database, refiner and synthesis result it writes.

Modules read it from here rather than from the package's ``__init__``, so that
no module imports back up through the package it belongs to.
"""

__version__ = "0.1.0"
