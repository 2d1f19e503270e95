"""gesturekit: controllable speech-driven gesture synthesis by motion matching.

An implementation of Habibie et al., "A Motion Matching-based Framework for
Controllable Gesture Synthesis from Speech" (SIGGRAPH 2022).
"""
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

__version__ = "0.1.0"

__all__ = [
    "AUDIO_SR",
    "AudioFileError",
    "ConfigError",
    "DatabaseError",
    "GestureKitError",
    "GestureKitWarning",
    "InputFileError",
    "Motion",
    "MotionFileError",
    "Take",
    "__version__",
]
