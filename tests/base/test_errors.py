"""gesturekit's warnings: issued as GestureKitWarning, or collected per thread."""

import io
import threading
import warnings

import numpy as np
import pytest
import soundfile as sf

from gesturekit.errors import GestureKitWarning, collect_warnings, warn
from gesturekit.interactive import read_speech_upload
from tests.waits import patience


def test_warn_issues_a_gesturekit_warning_outside_a_collection():
    with pytest.warns(GestureKitWarning, match="trimmed"):
        warn("trimmed")


def test_collections_nest_and_take_nothing_from_other_threads():
    started, release = threading.Event(), threading.Event()
    seen_by_other = []

    def other():
        with collect_warnings() as mine:
            started.set()
            assert release.wait(patience(120))
            warn("from the other thread")
        seen_by_other.extend(mine)

    t = threading.Thread(target=other)
    t.start()
    assert started.wait(patience(120))
    with warnings.catch_warnings():
        warnings.simplefilter("error", GestureKitWarning)  # nothing may escape the collections
        with collect_warnings() as outer:
            warn("a")
            with collect_warnings() as inner:
                warn("b")
                release.set()
                t.join(5)
            warn("c")
    assert outer == ["a", "c"] and inner == ["b"]
    assert seen_by_other == ["from the other thread"]
    with pytest.warns(GestureKitWarning):  # after the block, warnings are issued again
        warn("d")


def test_the_app_sees_a_silent_upload_while_another_thread_swaps_warning_state():
    # warnings.catch_warnings swaps process-wide state: a thread entering and leaving it
    # (torch's import does) must not hide a warning collected in another thread
    stop = threading.Event()

    def churn():
        while not stop.is_set():
            with warnings.catch_warnings(record=True):
                warnings.simplefilter("ignore")

    t = threading.Thread(target=churn)
    t.start()
    try:
        buf = io.BytesIO()
        sf.write(buf, np.zeros(16000, np.float32), 16000, format="WAV")
        for _ in range(20):
            with collect_warnings() as notes:
                read_speech_upload("quiet.wav", buf.getvalue())
            assert notes == ["quiet.wav: the audio is silent (peak level at or below -80 dBFS)"]
    finally:
        stop.set()
        t.join(5)
