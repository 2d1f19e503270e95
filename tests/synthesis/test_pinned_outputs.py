"""Synthesis outputs pinned by hash: a restructuring that changes one byte of what a user gets fails here.

Each case synthesises a fixed speech on a fixed database and hashes everything the user keeps: the
motion's positions (the refined and the k-NN ones), the search's choices and its recorded
candidates. The digests were made by this test; where a deliberate change of behaviour moves one,
the new digest is written here with the reason in the commit.

The digests are of exact bytes, so they hold for the numeric libraries and the CPU features they
were made with (``ENVIRONMENT``). Elsewhere (another BLAS kernel or SIMD width can move a float by
an ulp), the choices still have to match exactly and the positions to within 1e-5 m of the pinned
sums; the test says which of the two it checked.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from gesturekit.database import MatchingDatabase
from gesturekit.synthesis import SynthesisConfig, synthesize, synthesize_batch

pytestmark = pytest.mark.slow

CONFIGS = {
    "default": SynthesisConfig(),
    "controlled": SynthesisConfig(
        k=2, seed=3, init="rest", blend="offset", control="0-2:left_hand=high,2-4:speed=slow", record=5
    ),
}


def environment() -> str:
    """The numeric libraries and CPU features a digest of exact bytes depends on."""
    import librosa

    parts = [f"numpy {np.__version__}", f"librosa {librosa.__version__}"]
    try:
        import torch

        parts.append(f"torch {torch.__version__} {torch.backends.cpu.get_cpu_capability()}")
    except ImportError:
        parts.append("no torch")
    from numpy._core._multiarray_umath import __cpu_features__ as features

    parts.append("simd " + ",".join(sorted(k for k, v in features.items() if v)))
    try:
        import threadpoolctl

        parts += sorted(f"{i['internal_api']} {i.get('architecture')}" for i in threadpoolctl.threadpool_info())
    except ImportError:
        pass
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:16]


def digest(arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name} {a.dtype.str} {a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()[:20]


def summary(result) -> dict:
    """What is compared exactly everywhere (choices) and what within 1e-5 m (position sums)."""
    search = result.search
    choices = {name: getattr(search, name) for name in ("clip", "start", "frames", "cand_clip", "cand_start")}
    motions = {"motion": result.motion.positions, "knn": result.knn_motion.positions}
    return {
        "bytes": digest({**search.array_fields(), **motions}),
        "choices": digest(choices),
        "sums": {k: np.asarray(v, np.float64).sum(axis=(0, 1)).round(6).tolist() for k, v in motions.items()},
        "frames": int(len(result.motion.positions)),
    }


def check(case: str, got: dict, pinned: dict) -> None:
    assert got["frames"] == pinned[case]["frames"], case
    assert got["choices"] == pinned[case]["choices"], f"{case}: the search chose differently"
    if pinned["environment"] == environment():
        assert got["bytes"] == pinned[case]["bytes"], f"{case}: the output bytes changed"
    else:  # another numeric environment: exact choices, positions within 1e-5 m per frame
        for k, sums in got["sums"].items():
            np.testing.assert_allclose(sums, pinned[case]["sums"][k], atol=1e-5 * got["frames"] * 55)


@pytest.fixture(scope="module")
def demo_db(tmp_path_factory) -> MatchingDatabase:
    from gesturekit.demo import build_demo_database

    path = tmp_path_factory.mktemp("pinned") / "demo"
    build_demo_database(path, minutes=2)
    return MatchingDatabase.load(path)


@pytest.fixture(scope="module")
def speeches():
    from gesturekit.datasets.synthetic import generate_demo_take

    return [generate_demo_take(seconds=6.0, seed=s, name=f"q{s}")[0].audio for s in (11, 12)]


def run_demo(db, speeches) -> dict:
    from gesturekit.live import LiveSynthesizer

    out = {}
    for name, config in CONFIGS.items():
        out[f"demo/{name}"] = summary(synthesize(speeches[0], db=db, config=config))
    for i, res in enumerate(synthesize_batch(speeches, db=db, config=CONFIGS["controlled"])):
        out[f"demo/batch{i}"] = summary(res)
    live = LiveSynthesizer(db, config=CONFIGS["controlled"])
    for pos in range(0, len(speeches[1]), 2400):
        live.push(speeches[1][pos : pos + 2400])
    live.finish()
    out["demo/live"] = summary(live.result())
    try:
        from gesturekit.refine import open_refiner

        refiner = open_refiner("demo")
    except ImportError:
        return out
    out["demo/refined"] = summary(synthesize(speeches[0], db=db, config=CONFIGS["controlled"], refiner=refiner))
    return out


PINNED: dict = {
    "environment": "0d9868c14efe2828",
    "demo/default": {
        "bytes": "6418058daafc85a2d77c",
        "choices": "fc75df508aea7c7fcecf",
        "sums": {"motion": [-29.648089, 1786.97418, 845.533689], "knn": [-29.648089, 1786.97418, 845.533689]},
        "frames": 90,
    },
    "demo/controlled": {
        "bytes": "1d1e6bd3cc52358f6364",
        "choices": "feb3d6ac2ee568ac7359",
        "sums": {"motion": [24.065424, 1348.9367, 816.020915], "knn": [25.609519, 1289.346725, 794.384651]},
        "frames": 90,
    },
    "demo/batch0": {
        "bytes": "1d1e6bd3cc52358f6364",
        "choices": "feb3d6ac2ee568ac7359",
        "sums": {"motion": [24.065424, 1348.9367, 816.020915], "knn": [25.609519, 1289.346725, 794.384651]},
        "frames": 90,
    },
    "demo/batch1": {
        "bytes": "e09724e09877618b80ac",
        "choices": "b5ee02cc45ba214e9b0f",
        "sums": {"motion": [-131.927824, 1622.415852, 953.724002], "knn": [-133.360028, 1617.505053, 956.464748]},
        "frames": 90,
    },
    "demo/live": {
        "bytes": "e09724e09877618b80ac",
        "choices": "b5ee02cc45ba214e9b0f",
        "sums": {"motion": [-131.927824, 1622.415852, 953.724002], "knn": [-133.360028, 1617.505053, 956.464748]},
        "frames": 90,
    },
    "demo/refined": {
        "bytes": "ab74f9e66636d80072d6",
        "choices": "feb3d6ac2ee568ac7359",
        "sums": {"motion": [25.599992, 1289.58232, 794.369446], "knn": [25.609519, 1289.346725, 794.384651]},
        "frames": 90,
    },
    "zeggs/default": {
        "bytes": "2202e7e1afe1b60e1b7d",
        "choices": "3ed0d2b9741964309095",
        "sums": {"motion": [-194.198939, 1975.106273, 1039.577819], "knn": [-194.198939, 1975.106273, 1039.577819]},
        "frames": 90,
    },
    "zeggs/controlled": {
        "bytes": "f497c0faf7f463b87e4e",
        "choices": "fe7ca22f4dbdd7566eca",
        "sums": {"motion": [-219.605951, 2242.304869, 1045.082294], "knn": [-216.404707, 2214.545739, 1034.937983]},
        "frames": 90,
    },
}


def test_demo_outputs_are_pinned(demo_db, speeches):
    got = run_demo(demo_db, speeches)
    for case, summ in got.items():
        check(case, summ, PINNED)


def run_zeggs(folder, out, speeches) -> dict:
    from gesturekit.cli import main

    assert main(["build-db", str(folder), "--preset", "zeggs", "--out", str(out)]) == 0
    db = MatchingDatabase.load(out)
    return {f"zeggs/{name}": summary(synthesize(speeches[0], db=db, config=c)) for name, c in CONFIGS.items()}


def test_zeggs_outputs_are_pinned(zeggs_files, tmp_path, speeches):
    got = run_zeggs(zeggs_files[0].parent, tmp_path / "zeggs", speeches)
    for case, summ in got.items():
        check(case, summ, PINNED)
