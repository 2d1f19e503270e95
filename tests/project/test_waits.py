"""The one way tests wait (tests/waits.py): on a condition, with a deadline that only ends a hang."""

from __future__ import annotations

import pytest

from tests import waits


def test_wait_until_returns_the_first_true_value_and_checks_until_then():
    calls = []

    def condition():
        calls.append(None)
        return len(calls) >= 4 and {"answer": len(calls)}

    assert waits.wait_until(condition, what="the fourth check", interval_s=0) == {"answer": 4}
    assert len(calls) == 4  # not one check more


def test_wait_until_says_what_it_waited_for_when_the_deadline_passes():
    with pytest.raises(AssertionError, match=r"^the server answers: not within 0\.0\d* s$"):
        waits.wait_until(lambda: False, what="the server answers", timeout_s=0.01 / waits.PATIENCE, interval_s=0)


def test_give_up_ends_the_wait_at_once_with_its_reason():
    checks = []
    with pytest.raises(AssertionError, match="the server answers: gave up waiting, it exited with 3"):
        waits.wait_until(
            lambda: checks.append(None),
            what="the server answers",
            timeout_s=3600,
            give_up=lambda: "it exited with 3" if len(checks) >= 2 else None,
        )
    assert len(checks) == 2


@pytest.mark.parametrize("text, factor", [("", 1.0), ("1", 1.0), ("2.5", 2.5), (" 4 ", 4.0)])
def test_patience_scales_by_the_environment(monkeypatch, text, factor):
    monkeypatch.setenv("GESTUREKIT_TEST_PATIENCE", text)
    assert waits._factor() == factor


@pytest.mark.parametrize("text", ["0", "-1", "nan", "inf", "fast"])
def test_a_patience_that_is_no_positive_number_is_refused(monkeypatch, text):
    monkeypatch.setenv("GESTUREKIT_TEST_PATIENCE", text)
    with pytest.raises(ValueError, match=f"GESTUREKIT_TEST_PATIENCE must be a positive number, got '{text}'"):
        waits._factor()


def test_hypothesis_measures_no_time():
    """No per-example deadline, no health check on generation time; a test naming its own health
    checks to suppress replaces the profile's list, so it must name too_slow too."""
    import re
    from pathlib import Path

    from hypothesis import HealthCheck, settings

    assert settings.default.deadline is None
    assert HealthCheck.too_slow in settings.default.suppress_health_check
    tests = Path(__file__).resolve().parents[1]
    sources = [p for p in sorted(tests.rglob("*.py")) if p != Path(__file__).resolve()]
    lists = [
        (path.name, m.group(1))
        for path in sources
        for m in re.finditer(r"suppress_health_check=\[([^\]]*)\]", path.read_text(encoding="utf-8"))
    ]
    assert lists and all("too_slow" in names for _, names in lists), [n for n in lists if "too_slow" not in n[1]]
    timed = [path.name for path in sources for m in re.finditer(r"deadline=(?!None)", path.read_text(encoding="utf-8"))]
    assert timed == []
