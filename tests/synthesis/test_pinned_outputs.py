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
    "paper": SynthesisConfig(blend="none"),  # the paper's hard joins (the default until inertialization)
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
    "demo/paper": {
        "bytes": "8a81b970851cc7a57a93",
        "choices": "d49f4ffbd0b3b2a30951",
        "sums": {"motion": [142.776954, 844.33802, 770.059772], "knn": [142.776954, 844.33802, 770.059772]},
        "frames": 90,
    },
    "demo/default": {
        "bytes": "49476b33435849fa9366",
        "choices": "d49f4ffbd0b3b2a30951",
        "sums": {"motion": [139.326195, 848.893561, 775.529089], "knn": [142.776954, 844.33802, 770.059772]},
        "frames": 90,
    },
    "demo/controlled": {
        "bytes": "39084985a08bfab0a122",
        "choices": "fc9dde501b8e76dcd03c",
        "sums": {"motion": [132.023523, 1005.230578, 708.53893], "knn": [123.866636, 972.769752, 670.420214]},
        "frames": 90,
    },
    "demo/batch0": {
        "bytes": "39084985a08bfab0a122",
        "choices": "fc9dde501b8e76dcd03c",
        "sums": {"motion": [132.023523, 1005.230578, 708.53893], "knn": [123.866636, 972.769752, 670.420214]},
        "frames": 90,
    },
    "demo/batch1": {
        "bytes": "72aae7c2416533066642",
        "choices": "5753fb59ff1966280f13",
        "sums": {"motion": [55.873812, 1566.250661, 855.884925], "knn": [70.576929, 1544.056868, 856.183737]},
        "frames": 90,
    },
    "demo/live": {
        "bytes": "72aae7c2416533066642",
        "choices": "5753fb59ff1966280f13",
        "sums": {"motion": [55.873812, 1566.250661, 855.884925], "knn": [70.576929, 1544.056868, 856.183737]},
        "frames": 90,
    },
    "demo/refined": {
        "bytes": "e40f6f7bc24d7881ea35",
        "choices": "fc9dde501b8e76dcd03c",
        "sums": {"motion": [126.222259, 968.691714, 684.536812], "knn": [123.866636, 972.769752, 670.420214]},
        "frames": 90,
    },
    "zeggs/paper": {
        "bytes": "2202e7e1afe1b60e1b7d",
        "choices": "3ed0d2b9741964309095",
        "sums": {"motion": [-194.198939, 1975.106273, 1039.577819], "knn": [-194.198939, 1975.106273, 1039.577819]},
        "frames": 90,
    },
    "zeggs/default": {
        "bytes": "516ae8652120a315106b",
        "choices": "3ed0d2b9741964309095",
        "sums": {"motion": [-202.956821, 1978.308855, 1040.569814], "knn": [-194.198939, 1975.106273, 1039.577819]},
        "frames": 90,
    },
    "zeggs/controlled": {
        "bytes": "1445f9029995c57a5f97",
        "choices": "fe7ca22f4dbdd7566eca",
        "sums": {"motion": [-225.485004, 2244.604973, 1054.74908], "knn": [-216.404707, 2214.545739, 1034.937983]},
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
