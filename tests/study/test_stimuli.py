"""User-study stimuli: the balanced design, opaque ids, the stimuli command, and the Dask path."""

import hashlib
import re
import subprocess
from collections import Counter

import numpy as np
import pandas as pd
import pytest
import soundfile as sf
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.cli import main
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.demo import build_demo_database
from gesturekit.errors import ConfigError
from gesturekit.evaluate.baselines import SystemUnavailable
from gesturekit.export.video import ffmpeg_executable, probe_media
from gesturekit.study.stimuli import (
    balanced_latin_square,
    make_stimuli,
    measure_loudness,
    normalise_loudness,
    plan_stimuli,
    stimulus_id,
)

SYSTEMS = ["knn", "random", "audio-only"]


@pytest.fixture(scope="module")
def demo_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("demo") / "db"
    build_demo_database(path, minutes=2.0)
    return path


@pytest.fixture(scope="module")
def speech_folder(tmp_path_factory):
    """Three speeches of 1.2, 1.6 and 2.0 s (whole frames at 15 fps) at very different levels."""
    folder = tmp_path_factory.mktemp("speech")
    for i, (seconds, gain) in enumerate([(1.2, 1.0), (1.6, 0.1), (2.0, 0.4)]):
        take, _ = generate_demo_take(seconds=max(seconds, 2.0), seed=50 + i, name=f"s{i}")
        sf.write(folder / f"speech_{i}.wav", take.audio[: int(seconds * 16000)] * gain, 16000)
    return folder


@settings(max_examples=30, deadline=None)
@given(st.integers(1, 9))
def test_balanced_latin_square(n):
    sq = balanced_latin_square(n)
    assert sq.shape == (n if n % 2 == 0 or n == 1 else 2 * n, n)
    for row in sq:
        assert sorted(row) == list(range(n))
    for col in sq.T:  # every condition equally often at every position
        assert set(Counter(col).values()) == {len(sq) // n}
    pairs = Counter((a, b) for row in sq for a, b in zip(row, row[1:]))
    if n > 1:  # every condition directly after every other equally often
        assert len(pairs) == n * (n - 1) and len(set(pairs.values())) == 1


def test_plan_is_balanced_seeded_and_opaque():
    speeches = ["a.wav", "b.wav", "c.wav"]
    plan = plan_stimuli(speeches, SYSTEMS, seed=7)
    again = plan_stimuli(speeches, SYSTEMS, seed=7)
    pd.testing.assert_frame_equal(plan.conditions, again.conditions)
    pd.testing.assert_frame_equal(plan.order, again.order)
    other = plan_stimuli(speeches, SYSTEMS, seed=8)
    assert set(other.conditions["id"]).isdisjoint(plan.conditions["id"])
    assert all(re.fullmatch(r"[0-9a-f]{10}", i) for i in plan.conditions["id"])
    assert plan.conditions["id"].tolist()[0] == stimulus_id(7, "a.wav", "knn")
    order = plan.order
    assert order["participant"].nunique() == 6  # rows of the balanced square of 3 systems
    system_of = dict(zip(plan.conditions["id"], plan.conditions["system"]))
    for _, seen in order.groupby("participant"):
        assert sorted(seen["id"]) == sorted(plan.conditions["id"])  # every stimulus once
        assert seen["slot"].tolist() == list(range(1, 10))
    # over the participants every system is shown equally often at every position of every trial
    counts = Counter((t, p, system_of[i]) for t, p, i in zip(order["trial"], order["position"], order["id"]))
    assert set(counts.values()) == {2}
    with pytest.raises(ConfigError, match="unique"):
        plan_stimuli(["a", "a"], SYSTEMS)


def test_loudness_normalisation():
    rng = np.random.default_rng(0)
    t = np.arange(32000) / 16000
    quiet = (0.01 * np.sin(2 * np.pi * 200 * t) * (1 + 0.3 * rng.normal(size=t.size))).astype(np.float32)
    out, gain = normalise_loudness(quiet, target_lufs=-23.0)
    assert measure_loudness(out) == pytest.approx(-23.0, abs=0.3)
    assert gain > 0
    loud = (0.95 * np.sign(np.sin(2 * np.pi * 3 * t))).astype(np.float32)  # cannot be raised past its peak
    out, gain = normalise_loudness(loud, target_lufs=0.0, peak=0.98)
    assert np.abs(out).max() <= 0.98 + 1e-6
    silent, gain = normalise_loudness(np.zeros(16000, np.float32))
    assert gain == 0.0 and not silent.any()


def _soundtrack_loudness(path) -> float:
    raw = subprocess.run(
        [
            ffmpeg_executable(),
            "-nostdin",
            "-loglevel",
            "error",
            "-i",
            f"file:{path}",
            "-f",
            "f32le",
            "-ac",
            "1",
            "-ar",
            "16000",
            "-",
        ],
        capture_output=True,
        check=True,
    ).stdout
    return measure_loudness(np.frombuffer(raw, dtype="<f4"))


@pytest.mark.slow
def test_stimuli_command_three_speeches_by_three_systems(demo_path, speech_folder, tmp_path, capsys):
    out = tmp_path / "study"
    args = [
        "stimuli",
        "--db",
        str(demo_path),
        "--audio",
        str(speech_folder),
        "--systems",
        ",".join(SYSTEMS),
        "--out",
        str(out),
        "--resolution",
        "320x240",
        "--seed",
        "3",
    ]
    assert main(args) == 0
    assert "9 stimuli" in capsys.readouterr().out
    videos = sorted((out / "videos").iterdir())
    assert len(videos) == 9
    manifest = pd.read_csv(out / "manifest.csv")
    order = pd.read_csv(out / "order.csv")
    assert list(manifest.columns) == ["id", "file", "audio", "system", "controls", "seed", "duration_s"]
    assert sorted(manifest["file"]) == sorted(f"videos/{v.name}" for v in videos)
    assert not any((out / "videos" / n).exists() for n in ("manifest.csv", "order.csv"))  # kept apart
    for v in videos:  # the names say nothing of the system or the speech
        assert re.fullmatch(r"[0-9a-f]{10}\.mp4", v.name)
        assert not any(word in v.name for word in ("knn", "rand", "audio", "speech", "gt"))
    durations = dict(zip(manifest["id"], manifest["duration_s"]))
    assert sorted(set(durations.values())) == [1.2, 1.6, 2.0]
    loudness = []
    for v in videos:
        info = probe_media(v)
        vid, aud = info["video"], info["audio"]
        assert (vid["codec"], vid["width"], vid["height"], vid["fps"]) == ("h264", 320, 240, 15.0)
        assert vid["duration"] == pytest.approx(durations[v.stem], abs=1e-6)
        assert aud["duration"] == pytest.approx(durations[v.stem], abs=0.005)
        loudness.append(_soundtrack_loudness(v))
    assert max(loudness) - min(loudness) < 1.0  # inputs differed by 20 dB
    assert sorted(order["id"].unique()) == sorted(manifest["id"])
    assert order["participant"].nunique() == 6
    assert main(args) == 2  # an existing study needs --force
    assert "already exists here" in capsys.readouterr().err


def test_gt_needs_held_out_parts_and_knn_cgan_a_refiner(demo_path, speech_folder, tmp_path):
    db = MatchingDatabase.load(demo_path)
    with pytest.raises(SystemUnavailable, match="held-out parts"):
        make_stimuli(db, out=tmp_path / "a", audio=[speech_folder], systems="gt,knn")
    with pytest.raises(SystemUnavailable, match="refiner"):
        make_stimuli(db, out=tmp_path / "b", audio=[speech_folder], systems="knn,knn+cgan")


@pytest.mark.parametrize("lufs", [float("nan"), float("inf")])
def test_a_loudness_that_is_not_a_number_is_refused_before_any_work(demo_path, speech_folder, tmp_path, lufs):
    db = MatchingDatabase.load(demo_path)
    with pytest.raises(ConfigError, match="finite number of LUFS"):
        make_stimuli(db, out=tmp_path / "a", audio=[speech_folder], systems="knn", loudness_lufs=lufs)
    assert not (tmp_path / "a").exists()


@pytest.mark.slow
def test_dask_cluster_gives_the_same_study_as_local_processes(demo_path, speech_folder, tmp_path):
    from distributed import LocalCluster

    db = MatchingDatabase.load(demo_path)
    options = dict(
        holdouts=["demo0_000:10-11.2", "demo0_000:30-31.6"], systems="gt,knn", resolution=(160, 120), seed=11
    )
    local = make_stimuli(db, out=tmp_path / "local", workers=1, **options)
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, host="127.0.0.1", protocol="tcp://", dashboard_address=None
    ) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        remote = make_stimuli(db, out=tmp_path / "dask", scheduler=cluster.scheduler_address, **options)
    pd.testing.assert_frame_equal(local.manifest, remote.manifest)
    pd.testing.assert_frame_equal(local.order, remote.order)
    assert set(local.manifest["audio"]) == {"demo0_000:10-11.2", "demo0_000:30-31.6"}
    assert local.manifest["duration_s"].tolist() == [1.2, 1.2, 1.6, 1.6]
    for a, b in zip(local.videos, remote.videos):
        assert a.name == b.name
        assert hashlib.sha256(a.read_bytes()).hexdigest() == hashlib.sha256(b.read_bytes()).hexdigest()
