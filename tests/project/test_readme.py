"""The README's Python example runs as written, on the demo database and its refiner."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.refine import default_refiner_path

README = Path(__file__).resolve().parents[2] / "README.md"


def python_example() -> str:
    text = README.read_text(encoding="utf-8")
    match = re.search(r"### From Python\n```python\n(.*?)```", text, re.S)
    assert match, "the README has no Python example under 'From Python'"
    return match.group(1)


@pytest.mark.slow
def test_the_readme_python_example_runs(demo_home, tmp_path, monkeypatch):
    code = python_example()
    # the example's folders are a user's; here they are the demo database and the shipped refiner
    assert '"db/zeggs"' in code and '"models/zeggs-refiner"' in code
    code = code.replace('"db/zeggs"', repr(str(demo_home / "db" / "demo")))
    code = code.replace('"models/zeggs-refiner"', repr(str(default_refiner_path())))
    monkeypatch.chdir(tmp_path)
    take, _ = generate_demo_take(seconds=5.0, seed=11, name="speech")
    sf.write("speech.wav", take.audio, 16000)
    Path("out").mkdir()

    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)

    res, res2, refined, row = scope["res"], scope["res2"], scope["refined"], scope["row"]
    assert res.motion.positions.shape == (int(5.0 * 15), 55, 3)
    for name in ("speech.npz", "speech.bvh", "speech.mp4"):
        assert (tmp_path / "out" / name).stat().st_size > 0, name
    assert refined.refined_motion is not None and not np.array_equal(refined.motion.positions, res.motion.positions)
    # the pinned candidate is used at step 5, and the steps before it are unchanged
    assert (res2.search.clip[5], res2.search.start[5]) == (row["clip"], row["start"])
    np.testing.assert_array_equal(res2.search.clip[:5], res.search.clip[:5])
    assert res.plan.config == res.config.search
