"""The README stays a front page (what it is, the two commands, the CPU torch install, a picture,
links into the docs), and the Python examples of the README and of the synthesis guide (where the
README's manual moved) run as written, on the demo database and its refiner."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from gesturekit.cli import build_parser
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.refine import default_refiner_path

REPO = Path(__file__).resolve().parents[2]
README = REPO / "README.md"
GUIDES = REPO / "docs" / "guides"

#: The two commands on a fresh machine, exactly as the README gives them (.ci/run runs TEST as written).
LAUNCH = "PIP_RETRIES=1 pip install --no-compile -r requirements.txt && gesturekit app\n"
TEST = "PIP_RETRIES=1 pip install --no-compile -r requirements-test.txt && python -m pytest -n 2\n"


def python_block(text: str, heading: str = "") -> str:
    """The first Python code block after ``heading`` (a regular expression)."""
    match = re.search(rf"{heading}.*?```python\n(.*?)```", text, re.S)
    assert match, f"no Python example after {heading!r}"
    return match.group(1)


def run_example(code: str, where: str, demo_home: Path, tmp_path: Path, monkeypatch) -> dict:
    """Run ``code`` in ``tmp_path`` beside 5 s of generated speech.wav, with the example's folders
    (a user's) replaced by the demo database and the shipped refiner."""
    assert '"db/zeggs"' in code
    code = code.replace('"db/zeggs"', repr(str(demo_home / "db" / "demo")))
    code = code.replace('"models/zeggs-refiner"', repr(str(default_refiner_path())))
    monkeypatch.chdir(tmp_path)
    take, _ = generate_demo_take(seconds=5.0, seed=11, name="speech")
    sf.write("speech.wav", take.audio, 16000)
    Path("out").mkdir()
    scope: dict = {}
    exec(compile(code, where, "exec"), scope)
    return scope


def test_the_readme_is_a_front_page():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) < 200, "the README is a front page: the manual is in docs/"
    blocks = re.findall(r"```bash\n(.*?)```", text, re.S)
    assert any(b.endswith(LAUNCH) for b in blocks), "the README lost its install-and-launch command"
    assert any(b.endswith(TEST) for b in blocks), "the README lost its install-and-test command"
    assert "pip install torch --index-url https://download.pytorch.org/whl/cpu" in text
    pictures = re.findall(r"!\[[^]]+\]\(([^)]+)\)", text)
    assert pictures, "the README shows the app"
    for picture in pictures:
        assert (REPO / picture).stat().st_size < 200_000, f"{picture} is not small"
    for page in ("METHOD.md", "guides/databases.md", "guides/synthesis.md", "guides/errors.md", "examples.md"):
        assert f"](docs/{page})" in text, f"the README does not link docs/{page}"


@pytest.mark.slow
def test_the_readme_python_example_runs(demo_home, tmp_path, monkeypatch):
    scope = run_example(
        python_block(README.read_text(encoding="utf-8"), "## Using it"), "README.md", demo_home, tmp_path, monkeypatch
    )
    assert scope["res"].motion.positions.shape == (int(5.0 * 15), 55, 3)


@pytest.mark.slow
def test_the_synthesis_guide_python_example_runs(demo_home, tmp_path, monkeypatch):
    guide = GUIDES / "synthesis.md"
    code = python_block(guide.read_text(encoding="utf-8"), "## From Python")
    assert '"models/zeggs-refiner"' in code
    scope = run_example(code, str(guide), demo_home, tmp_path, monkeypatch)

    res, res2, refined, row = scope["res"], scope["res2"], scope["refined"], scope["row"]
    assert res.motion.positions.shape == (int(5.0 * 15), 55, 3)
    for name in ("speech.npz", "speech.bvh", "speech.mp4"):
        assert (tmp_path / "out" / name).stat().st_size > 0, name
    assert refined.refined_motion is not None and not np.array_equal(refined.motion.positions, res.motion.positions)
    # the pinned candidate is used at step 5, and the steps before it are unchanged
    assert (res2.search.clip[5], res2.search.start[5]) == (row["clip"], row["start"])
    np.testing.assert_array_equal(res2.search.clip[:5], res.search.clip[:5])
    assert res.plan.config == res.config.search


def cli_options(parser: argparse.ArgumentParser, command: tuple[str, ...] = ()):
    """(command, option) for every long option of every command of the command line."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*command, name), None
                yield from cli_options(sub, (*command, name))
        else:
            for option in action.option_strings:
                if option.startswith("--") and option != "--help":
                    yield command, option


def test_every_command_and_option_is_documented_in_a_guide():
    guides = "\n".join(p.read_text(encoding="utf-8") for p in sorted(GUIDES.glob("*.md")))
    options = list(cli_options(build_parser()))
    assert len(options) > 100
    missing = [
        " ".join(("gesturekit", *command)) + (f" {option}" if option else "")
        for command, option in options
        if (option or "gesturekit " + " ".join(command)) not in guides
    ]
    assert not missing, f"not documented in docs/guides/: {missing}"
