"""Running a user study on a stimuli folder: its design, the participant pages, the check media,
HEMVIP interop (this part), the participant server and response store, the analysis.

A study folder is what :func:`gesturekit.study.make_stimuli` writes; ``gesturekit study init``
adds ``design.json`` (:mod:`.design`) and the attention- and audio-check media in ``checks/``
(:mod:`.media`).
"""

from __future__ import annotations

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
