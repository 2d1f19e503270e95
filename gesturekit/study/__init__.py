"""The user study, from stimuli to analysis: the stimuli (:mod:`.stimuli`, their options
:mod:`.config`), and running a study on a stimuli folder: its design, the participant pages, the
check media, HEMVIP interop (this part), the participant server and response store, the analysis.

A study folder is what :func:`gesturekit.study.stimuli.make_stimuli` writes; ``gesturekit study init``
adds ``design.json`` (:mod:`.design`) and the attention- and audio-check media in ``checks/``
(:mod:`.media`).
"""

from __future__ import annotations

from .._moved import moved_names
from .design import (
    Media,
    Page,
    StudyDesign,
    check_answer,
    hash_password,
    init_study,
    load_design,
    media_index,
    participant_pages,
    verify_password,
)

__all__ = [
    "Media",
    "Page",
    "StudyDesign",
    "check_answer",
    "hash_password",
    "init_study",
    "load_design",
    "media_index",
    "participant_pages",
    "verify_password",
]

# what gesturekit.study (the module that became .stimuli) gave, for one release
__getattr__ = moved_names(
    __name__,
    "gesturekit.study.stimuli",
    (
        "StimulusSpeech",
        "StudyResult",
        "stimulus_id",
        "balanced_latin_square",
        "plan_stimuli",
        "measure_loudness",
        "normalise_loudness",
        "speech_sources",
        "stimulus_style",
        "StudyConfig",
        "make_stimuli",
    ),
)
