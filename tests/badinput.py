"""The bad-input suite's harness: run the command line as a user would and check that it fails cleanly.

A clean failure is exit status 2, one message on stderr that names the file
and says what is wrong, no traceback, and nothing that existed before changed.
:func:`run_cli` runs ``gesturekit.cli.main`` in this process (a subprocess per
case would cost a second of imports each); an exception that escapes ``main``
is turned into the traceback a user would have seen, so the assertions catch it.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import os
import traceback
from dataclasses import dataclass
from pathlib import Path

__all__ = ["CliRun", "run_cli", "snapshot", "assert_refused"]


@dataclass
class CliRun:
    """What one command printed and returned."""

    args: list[str]
    code: int
    stdout: str
    stderr: str


def run_cli(*args: str | os.PathLike) -> CliRun:
    """Run ``gesturekit ARGS`` in this process; never raises."""
    from gesturekit.cli import main

    argv = [os.fspath(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse's usage errors
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException:  # what a user would see as a traceback
            traceback.print_exc(file=err)
            code = 1
    return CliRun(argv, code, out.getvalue(), err.getvalue())


def snapshot(*roots: str | os.PathLike) -> dict[str, tuple]:
    """Every file and folder under ``roots``: path -> (kind, size, mtime_ns, sha1 of the bytes)."""
    state: dict[str, tuple] = {}
    for root in map(Path, roots):
        if not root.exists() and not root.is_symlink():
            state[str(root)] = ("absent",)
            continue
        items = [root] + (sorted(root.rglob("*")) if root.is_dir() else [])
        for p in items:
            if p.is_symlink():
                state[str(p)] = ("link", os.readlink(p))
            elif p.is_dir():
                state[str(p)] = ("dir",)
            elif not p.is_file():  # a FIFO or a device: reading it would block or never end
                state[str(p)] = ("special", p.stat().st_mode)
            else:
                st = p.stat()
                state[str(p)] = ("file", st.st_size, st.st_mtime_ns, hashlib.sha1(p.read_bytes()).hexdigest())
    return state


def assert_refused(
    run: CliRun, *, names: str | os.PathLike | None, problem: str | tuple[str, ...], before: dict | None = None
) -> None:
    """Assert a clean failure.

    Parameters
    ----------
    run : CliRun
    names : path or str, optional
        What the message must name (a file, a folder, an option); ``None`` when nothing is named.
    problem : str or tuple of str
        Words of the problem, matched case-insensitively; with a tuple, any one of them.
    before : dict, optional
        A :func:`snapshot` taken before the run; the same roots must be unchanged after it.
    """
    text = run.stderr
    assert run.code == 2, f"exit status {run.code}, expected 2; stderr:\n{text}"
    assert "Traceback" not in text, f"a traceback reached the user:\n{text}"
    assert "gesturekit: error:" in text, f"no error message:\n{text}"
    if names is not None:
        assert os.fspath(names) in text, f"the message does not name {os.fspath(names)!r}:\n{text}"
    words = (problem,) if isinstance(problem, str) else problem
    assert any(w.lower() in text.lower() for w in words), f"the message does not say {words!r}:\n{text}"
    if before is not None:
        roots = [k for k in before if not any(k.startswith(o + os.sep) for o in before if o != k)]
        after = snapshot(*roots)
        changed = sorted(set(before) ^ set(after) | {k for k in before if k in after and before[k] != after[k]})
        assert not changed, f"a failed run changed {changed[:5]}"
