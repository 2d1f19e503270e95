"""The matching database: takes -> features -> 64-frame clips, saved as a folder of plain arrays and JSON.

The package's modules, by idea:

================  =====================================================================
``matching``      :class:`MatchingDatabase`: the clips the search reads, opened or built
``config``        :class:`BuildConfig` (frozen): how a database is built;
                  :func:`normalise_exclusions`: the data a search holds out
``clips``         one take made into clips: features, the cut, its audio, its moments
``build``         the builder: takes' clips assembled into the database's arrays, in
                  memory or straight into a folder
``folder``        the folder format: its files, writing and reading them with every check
``audio``         how the takes' audio is kept (int16, a lower rate, FLAC)
``stage``         a build from files, first pass: takes staged on disk, in parallel, resumable
``stage_check``   whether a staged unit is whole enough to reuse
``sources``       a build from files: staging, assembling, appending (``gesturekit build-db``)
================  =====================================================================
"""

from .clips import TakeFeatures, take_features
from .config import BuildConfig, normalise_exclusions
from .folder import FORMAT_VERSION
from .matching import MatchingDatabase
from .stage import BuildProgress

__all__ = [
    "FORMAT_VERSION",
    "BuildConfig",
    "BuildProgress",
    "TakeFeatures",
    "take_features",
    "MatchingDatabase",
    "normalise_exclusions",
]
