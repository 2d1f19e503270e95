"""Waiting in tests: on the state a test needs, never for a fixed time.

A busy machine (CI beside other work, a load of 7-10 on 2 cores) makes everything slower by a
factor nobody knows in advance. So a test never sleeps and then asserts, and never gives a server,
a thread, a subprocess or a browser a short fixed time: it waits *for a condition*
(:func:`wait_until`, or Playwright's own ``wait_for``), and gives up only after a generous
deadline (:func:`patience`), which exists to end a hang, not to measure speed. A wait that
succeeds costs only the time its condition took, so a long deadline costs nothing.

``GESTUREKIT_TEST_PATIENCE`` scales every deadline (a positive number, default 1): set it higher
on a machine known to be overloaded, never lower to make a test faster.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def _factor() -> float:
    text = os.environ.get("GESTUREKIT_TEST_PATIENCE", "").strip() or "1"
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"GESTUREKIT_TEST_PATIENCE must be a positive number, got {text!r}")
    return value


PATIENCE = _factor()

#: the deadline of one Streamlit AppTest script run (``AppTest.from_file(..., default_timeout=APP_RUN_S)``)
APP_RUN_S = 300.0 * PATIENCE


def patience(seconds: float) -> float:
    """A deadline of ``seconds`` on a quiet machine, scaled by ``GESTUREKIT_TEST_PATIENCE``."""
    return seconds * PATIENCE


def wait_until(
    condition: Callable[[], T],
    *,
    what: str,
    timeout_s: float = 120.0,
    interval_s: float = 0.05,
    give_up: Callable[[], str | None] | None = None,
) -> T:
    """Call ``condition`` until it returns something true, and return that.

    Parameters
    ----------
    condition : callable
        Checks the state the test needs (a file exists, a server answers, a thread has ended).
    what : str
        The state, for the failure message ("the study server answers").
    timeout_s : float
        The deadline in seconds on a quiet machine (scaled by :func:`patience`): it ends a hang.
    interval_s : float
        The pause between checks, in seconds.
    give_up : callable, optional
        Returns a reason to stop waiting at once (a server process that exited), else None.

    Raises
    ------
    AssertionError
        When the deadline passes or ``give_up`` gives a reason; the message says what was awaited.
    """
    deadline = time.monotonic() + patience(timeout_s)
    while True:
        value = condition()
        if value:
            return value
        if give_up is not None and (reason := give_up()):
            raise AssertionError(f"{what}: gave up waiting, {reason}")
        if time.monotonic() > deadline:
            raise AssertionError(f"{what}: not within {patience(timeout_s):g} s")
        time.sleep(interval_s)
