"""gesturekit: controllable speech-driven gesture synthesis by motion matching.

An implementation of Habibie et al., "A Motion Matching-based Framework for
Controllable Gesture Synthesis from Speech" (SIGGRAPH 2022).
"""

from . import _moved
from ._version import __version__
from .control import ControlTrack, parse_control
from .database import BuildConfig, MatchingDatabase
from .errors import (
    AudioFileError,
    ConfigError,
    DatabaseError,
    GestureKitError,
    GestureKitWarning,
    InputFileError,
    MotionFileError,
)
from .motion import AUDIO_SR, Motion, Take
from .synthesis.synthesizer import Synthesizer

__all__ = [
    "AUDIO_SR",
    "AudioFileError",
    "BuildConfig",
    "ControlTrack",
    "ConfigError",
    "DatabaseError",
    "GestureKitError",
    "GestureKitWarning",
    "InputFileError",
    "MatchingDatabase",
    "Motion",
    "MotionFileError",
    "Synthesizer",
    "Take",
    "parse_control",
    "__version__",
]

_moved.install()  # the old paths of the modules that moved into packages, for one release
