"""CI runs what a new user runs: the README's test command, exactly as written, and the README's two
commands install alike (the same pip options, the test requirements on top of the app's)."""

from __future__ import annotations

import re
import shlex
import subprocess
from pathlib import Path

from tests.project.test_readme import LAUNCH, TEST

ROOT = Path(__file__).resolve().parents[2]
CI = ROOT / ".ci" / "run"


def commands(script: str) -> list[str]:
    """The lines of a shell script that run something: comments and blank lines left out."""
    return [line.strip() for line in script.splitlines() if line.strip() and not line.strip().startswith("#")]


def pip_options(command: str) -> tuple[list[str], str]:
    """(the environment it sets and the options of the ``pip install`` that begins ``command``, the
    requirements file it installs)."""
    words = shlex.split(command.split("&&")[0])
    env = []
    while words and re.fullmatch(r"[A-Z_]+=\S*", words[0]):
        env.append(words.pop(0))
    assert words[:2] == ["pip", "install"], command
    files = [words[i + 1] for i, w in enumerate(words) if w == "-r"]
    assert len(files) == 1, command
    options = [w for i, w in enumerate(words[2:], 2) if w != "-r" and words[i - 1] != "-r"]
    return env + options, files[0]


def test_ci_runs_the_readme_test_command_as_written():
    found = [line for line in commands(CI.read_text(encoding="utf-8")) if line.startswith(TEST.strip())]
    assert len(found) == 1, f".ci/run does not run the README's test command {TEST.strip()!r} as written"
    rest = found[0][len(TEST.strip()) :]
    assert rest == "" or re.fullmatch(r" \|\| failed\+=\(\"[^\"]+\"\)", rest), found[0]  # a failure is recorded
    # nothing else in CI installs the requirements another way
    others = [line for line in commands(CI.read_text(encoding="utf-8")) if "requirements" in line and line != found[0]]
    assert not others, others


def test_the_two_commands_install_with_the_same_pip_options():
    launch, launch_file = pip_options(LAUNCH.strip())
    test, test_file = pip_options(TEST.strip())
    assert launch == test, (launch, test)
    # the retries are set in the environment, where the pip that builds `-e .` reads them too
    assert "PIP_RETRIES=1" in launch and not any(o.startswith("--retries") for o in launch), launch
    assert "--no-compile" in launch, launch
    assert (launch_file, test_file) == ("requirements.txt", "requirements-test.txt")
    first = [line.strip() for line in (ROOT / test_file).read_text(encoding="utf-8").splitlines()]
    assert "-r requirements.txt" in first  # the test install is the app's install and more
    assert LAUNCH.strip().endswith("&& gesturekit app") and TEST.strip().endswith("&& python -m pytest -n 2")


def test_the_docs_front_page_gives_the_readmes_commands():
    text = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```bash\n(.*?)```", text, re.S)
    assert any(b.endswith(LAUNCH) for b in blocks) and any(b.endswith(TEST) for b in blocks)


def test_the_ci_script_parses():
    run = subprocess.run(["bash", "-n", str(CI)], capture_output=True, text=True, timeout=30)
    assert run.returncode == 0, run.stderr
