"""Refiner inference: any length, no seam every 64 frames, checkpoint loading, layout checks."""

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.blend import keep_slow
from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.errors import ConfigError, DatabaseError, InputFileError
from gesturekit.features import LAYOUT
from gesturekit.refine import default_refiner_path, load_refiner, open_refiner
from gesturekit.refine.infer import Refiner
from gesturekit.refine.model import ModelConfig, build_models
from gesturekit.refine.train import TrainConfig, train_refiner
from gesturekit.skeleton import JOINT_NAMES
from tests.conftest import make_take
from tests.refine_helpers import TINY, _one_torch_thread  # noqa: F401 (an autouse fixture)
from tests.waits import patience


def random_refiner(seed=0, channels=(8, 8, 8, 8)):
    gen, _ = build_models(ModelConfig(generator_channels=channels, critic_channels=(4, 4, 4)), seed=seed)
    # running statistics as after training, so the eval-mode network is not the identity of BN
    for m in gen.modules():
        if isinstance(m, torch.nn.BatchNorm1d):
            m.running_mean.uniform_(-0.2, 0.2, generator=torch.Generator().manual_seed(seed))
    stats = {
        "audio_mean": np.zeros(28, np.float32),
        "audio_std": np.ones(28, np.float32),
        "motion_mean": np.zeros(165, np.float32),
        "motion_std": np.full(165, 0.1, np.float32),
    }
    return Refiner(gen, stats=stats, config={"layout": LAYOUT.signature(), "joint_names": list(JOINT_NAMES)})


def smooth_inputs(T, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None] / 15.0
    motion = 0.1 * np.sin(2 * np.pi * rng.uniform(0.1, 0.8, (1, 165)) * t + rng.uniform(0, 6, (1, 165)))
    audio = np.sin(2 * np.pi * rng.uniform(0.2, 2.0, (1, 28)) * t + rng.uniform(0, 6, (1, 28)))
    return motion.astype(np.float32), audio.astype(np.float32)


@settings(max_examples=15, deadline=None)
@given(st.integers(1, 300), st.sampled_from([8, 16, 32, 64]), st.sampled_from(["windowed", "full"]))
def test_any_length_keeps_its_frames(T, hop, mode):
    ref = random_refiner()
    g, a = smooth_inputs(T)
    out = ref.refine(g, a, mode=mode, hop=hop)
    assert out.shape == (T, 165) and out.dtype == np.float32 and np.isfinite(out).all()
    # (T, 55, 3) motion is accepted as well
    np.testing.assert_array_equal(ref.refine(g.reshape(T, 55, 3), a, mode=mode, hop=hop), out)


def _seam_ratio(y):
    """Mean step |y[t+1] - y[t]| across frames 64 i - 1 -> 64 i over that across 8 j - 1 -> 8 j elsewhere.

    The generator's nearest up-sampling makes every 8th step special, so seams at multiples of
    64 are compared with the other multiples of 8.
    """
    d = np.abs(np.diff(y, axis=0)).mean(axis=1)
    t = np.arange(d.size)
    seam = (t % 64) == 63
    other = ((t % 8) == 7) & ~seam
    return d[seam].mean() / d[other].mean()


def test_ten_minutes_have_no_seam_every_64_frames():
    ref = random_refiner(seed=1)
    g, a = smooth_inputs(15 * 600, seed=1)
    windowed = ref.refine(g, a, mode="windowed")
    full = ref.refine(g, a, mode="full")
    assert windowed.shape == full.shape == (9000, 165)
    assert _seam_ratio(windowed) < 1.2
    assert _seam_ratio(full) < 1.2
    # the statistic does see seams: cutting into plain 64-frame windows leaves one at every cut
    n = 9000 // 64 * 64
    z = ((g[:n] - ref.stats["motion_mean"]) / ref.stats["motion_std"]).reshape(-1, 64, 165)
    az = a[:n].reshape(-1, 64, 28)
    with torch.no_grad():
        naive = ref.generator(torch.from_numpy(az), torch.from_numpy(z)).numpy().reshape(-1, 165)
    assert _seam_ratio(naive * ref.stats["motion_std"]) > 1.5


def test_windowed_and_full_agree_away_from_the_ends():
    # different padding at window ends is all that separates them; the Hann cross-fade hides it
    ref = random_refiner(seed=2)
    g, a = smooth_inputs(1000, seed=2)
    w, f = ref.refine(g, a, mode="windowed", hop=8), ref.refine(g, a, mode="full")
    spread = np.abs(f[64:-64] - f[64:-64].mean(axis=0)).mean()
    assert np.abs(w[64:-64] - f[64:-64]).mean() < 0.05 * spread


def test_bad_inputs_are_refused():
    ref = random_refiner()
    g, a = smooth_inputs(40)
    with pytest.raises(ConfigError, match="audio features must have shape"):
        ref.refine(g, a[:30])
    with pytest.raises(ConfigError, match="mode"):
        ref.refine(g, a, mode="fast")
    with pytest.raises(ConfigError, match="hop"):
        ref.refine(g, a, mode="windowed", hop=0)
    bad = g.copy()
    bad[3, 3] = np.nan
    with pytest.raises(ConfigError, match="NaN"):
        ref.refine(bad, a)


# ---- keeping the k-NN motion's slow content ----------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(st.integers(2, 400), st.floats(0.3, 1.5), st.integers(0, 2**31 - 1))
def test_keep_slow_takes_slow_content_from_knn_and_fast_content_from_the_refiner(T, hz, seed):
    rng = np.random.default_rng(seed)
    knn = rng.standard_normal((T, 6)).astype(np.float32)
    offset = rng.uniform(-1, 1, (1, 6))  # e.g. a hand pulled up by the refiner: slow content
    fast = 0.05 * (-1.0) ** np.arange(T)[:, None] * rng.uniform(0.5, 1, (1, 6))  # 7.5 Hz at 15 fps
    out = keep_slow(knn + offset + fast, knn, hz)
    assert out.shape == (T, 6) and out.dtype == np.float32
    # the offset is gone entirely; the fast alternation stays (a Gaussian passes exp(-ln2/2 (7.5/hz)^2)
    # of it, at most 0.02% here), apart from the ends, where the held edge values hold a part of it
    resid = out - knn - fast
    margin = int(4 * np.sqrt(np.log(2)) / (2 * np.pi * hz) * 15) + 1  # the filter's reach, frames
    if T > 2 * margin:
        assert np.abs(resid[margin:-margin]).max() < 2e-3 * 0.05 + 1e-5
    assert np.abs(resid).max() < 0.05 + 1e-5


def test_keep_slow_cuts_near_the_stated_frequency():
    T = 900
    t = np.arange(T)[:, None] / 15.0
    for f, kept_by_knn in ((0.25, True), (6.0, False)):
        wave = np.sin(2 * np.pi * f * t)
        out = keep_slow(wave, np.zeros((T, 1)), 2.0)
        # slow: the k-NN's (zero) wins; fast: the refiner's wave passes
        ratio = np.abs(out[100:-100]).max() / np.abs(wave[100:-100]).max()
        assert (ratio < 0.05) if kept_by_knn else (ratio > 0.9)
    # half power at the cut-off frequency
    wave = np.sin(2 * np.pi * 2.0 * t)
    low = wave - keep_slow(wave, np.zeros((T, 1)), 2.0)  # what the low-pass passed
    assert abs(np.sqrt((low[100:-100] ** 2).mean() / (wave[100:-100] ** 2).mean()) - np.sqrt(0.5)) < 0.02


def test_refine_is_the_generator_alone_unless_asked_to_keep_slow_content():
    ref = random_refiner(seed=3)
    g, a = smooth_inputs(200, seed=3)
    raw = ref.refine(g, a)
    np.testing.assert_array_equal(ref.refine(g, a, keep_below_hz=None), raw)
    np.testing.assert_allclose(ref.refine(g, a, keep_below_hz=1.0), keep_slow(raw, g, 1.0), atol=1e-6)
    # the random generator moves the motion far; keeping slow content pulls it back to the input
    assert np.abs(ref.refine(g, a, keep_below_hz=2.0) - g).mean() < 0.5 * np.abs(raw - g).mean()
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ConfigError, match="keep_below_hz"):
            ref.refine(g, a, keep_below_hz=bad)
    with pytest.raises(ConfigError, match="differ in shape"):
        keep_slow(raw, g[:10], 2.0)


# ---- checkpoint folders ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    base = tmp_path_factory.mktemp("refiner")
    takes = [make_take(12.0, seed=1, name="a"), make_take(10.0, seed=2, name="b")]
    db = MatchingDatabase.build(takes, config=BuildConfig(overlap_stride=16, store_audio=False))
    db.save(base / "db")
    db = MatchingDatabase.load(base / "db")
    out = train_refiner(db, base / "r", model=TINY, train=TrainConfig(iterations=5, batch_size=4), device="cpu")
    return db, out


def test_load_uses_weights_only_and_refines(tiny):
    db, out = tiny
    ref = Refiner.load(out)
    ref.check_database(db)
    state = torch.load(out / "generator.pt", weights_only=True)
    assert all(torch.equal(state[k], v) for k, v in ref.generator.state_dict().items())
    assert not ref.generator.training
    y = ref.refine(np.asarray(db.G[0]), np.asarray(db.A[0]))
    assert y.shape == (64, 165)
    # deterministic
    np.testing.assert_array_equal(y, Refiner.load(out).refine(np.asarray(db.G[0]), np.asarray(db.A[0])))


def test_a_database_with_another_layout_is_refused(tiny):
    db, out = tiny
    ref = Refiner.load(out)
    other = copy.copy(db)
    other.meta = json.loads(json.dumps(db.meta))
    other.meta["layout"]["n_mfcc"] = 20
    with pytest.raises(DatabaseError, match="another feature layout.*n_mfcc"):
        ref.check_database(other)


def test_check_refiner_reads_the_folder_without_torch_and_refuses_another_layout(tiny, tmp_path):
    import subprocess
    import sys

    from gesturekit.refine import check_refiner

    db, out = tiny
    assert check_refiner(out, db) == Path(out).resolve()
    other = copy.copy(db)
    other.meta = json.loads(json.dumps(db.meta))
    other.meta["layout"]["n_mels"] = 64
    with pytest.raises(DatabaseError, match="another feature layout.*n_mels"):
        check_refiner(out, other)
    with pytest.raises(InputFileError, match="no refiner folder"):
        check_refiner(tmp_path / "nothing", db)
    # the app checks a chosen folder on every page view: that must not import torch
    code = (
        "import sys; from gesturekit.database import MatchingDatabase; from gesturekit.refine import check_refiner; "
        f"check_refiner({str(out)!r}, MatchingDatabase.load({str(Path(db.path))!r})); "
        "assert 'torch' not in sys.modules, 'torch was imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=patience(300))


def test_a_refiner_of_another_layout_is_refused(tiny, tmp_path):
    _, out = tiny
    import shutil

    copy_dir = tmp_path / "r"
    shutil.copytree(out, copy_dir)
    cfg = json.loads((copy_dir / "config.json").read_text())
    cfg["layout"]["audio_offsets"] = [0, 1]
    (copy_dir / "config.json").write_text(json.dumps(cfg))
    with pytest.raises(DatabaseError, match="another feature layout"):
        Refiner.load(copy_dir)


def test_broken_folders_are_named_in_the_error(tmp_path):
    with pytest.raises(InputFileError, match="no refiner folder"):
        Refiner.load(tmp_path / "nothing")
    (tmp_path / "x").mkdir()
    with pytest.raises(InputFileError, match="config.json is missing"):
        Refiner.load(tmp_path / "x")
    (tmp_path / "x" / "config.json").write_text("{not json")
    with pytest.raises(InputFileError, match=r"x: config.json is not valid JSON"):
        Refiner.load(tmp_path / "x")
    (tmp_path / "x" / "config.json").write_text(json.dumps({"format": "gesturekit-refiner", "format_version": 99}))
    with pytest.raises(InputFileError, match="version 99"):
        Refiner.load(tmp_path / "x")


def test_the_shipped_demo_refiner_loads():
    path = default_refiner_path()
    if not (path / "config.json").is_file():
        pytest.skip(f"no demo refiner at {path}")
    ref = load_refiner("demo")
    size = sum(p.stat().st_size for p in path.iterdir())
    assert size < 2 * 1024 * 1024
    assert ref.config["preset"] == "quick" and ref.config["complete"]
    g, a = smooth_inputs(100)
    assert np.isfinite(ref.refine(g, a)).all()


# ---- config.json is checked against the structure training writes ---------------------------
from hypothesis import HealthCheck  # noqa: E402

from gesturekit.errors import GestureKitError  # noqa: E402
from gesturekit.refine.folder import read_refiner_config  # noqa: E402

_DEMO = Path(__file__).resolve().parents[2] / "gesturekit" / "assets" / "demo-refiner"
_json = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-3, 300)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=4),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=5,
)


@pytest.fixture(scope="module")
def demo_copy(tmp_path_factory):
    import shutil

    return Path(shutil.copytree(_DEMO, tmp_path_factory.mktemp("refiner") / "demo"))


@settings(
    max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(data=st.data())
def test_a_damaged_config_is_refused_or_loads(demo_copy, data):
    original = (demo_copy / "config.json").read_text()
    cfg = json.loads(original)
    places = [(cfg, k) for k in cfg if k not in ("format", "format_version")]
    places += [(cfg["model"], k) for k in cfg["model"]] + [(cfg["files"], k) for k in cfg["files"]]
    container, key = places[data.draw(st.integers(0, len(places) - 1), label="place")]
    if data.draw(st.booleans(), label="delete"):
        del container[key]
    else:
        container[key] = data.draw(_json, label="value")
    (demo_copy / "config.json").write_text(json.dumps(cfg))
    try:
        refiner = Refiner.load(demo_copy)
    except GestureKitError as exc:
        assert exc.path == str(demo_copy)
        return
    finally:
        (demo_copy / "config.json").write_text(original)
    assert refiner.window % 8 == 0


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda c: {**c, "files": list(c["files"])}, "'files' must be an object, found list"),
        (lambda c: {**c, "files": {"generator.pt": "abc"}}, "files.generator.pt must be the file's SHA-256"),
        (lambda c: {**c, "model": {**c["model"], "generator_channels": [32, "64"]}}, "model.generator_channels"),
        (lambda c: {**c, "model": {**c["model"], "window": True}}, "model.window must be a positive integer"),
        (lambda c: {**c, "iteration": 1.5}, "'iteration' must be an integer"),
        (lambda c: {**c, "resumable": "yes"}, "'resumable' must be true or false"),
        (lambda c: {**c, "training": []}, "'training' must be an object"),
        (lambda c: {k: v for k, v in c.items() if k != "joint_names"}, "'joint_names' must be a list"),
    ],
)
def test_config_of_the_wrong_structure_is_named(demo_copy, tmp_path, edit, message):
    import shutil

    folder = Path(shutil.copytree(demo_copy, tmp_path / "r"))
    cfg = json.loads((folder / "config.json").read_text())
    (folder / "config.json").write_text(json.dumps(edit(cfg)))
    with pytest.raises(InputFileError, match=message) as info:
        read_refiner_config(folder)
    assert info.value.path == str(folder)


@pytest.mark.parametrize(
    "stats, message",
    [
        (b"PK\x03\x04 truncated", "stats.npz cannot be read"),
        ({"audio_mean": np.array([None], dtype=object)}, "stats.npz cannot be read"),
        (
            {
                "audio_mean": np.zeros(28),
                "audio_std": np.ones(28),
                "motion_mean": np.zeros(165),
                "motion_std": np.full(165, np.inf),
            },
            "motion_std must be a vector of finite numbers",
        ),
        (
            {
                "audio_mean": np.zeros(28),
                "audio_std": np.ones(27),
                "motion_mean": np.zeros(165),
                "motion_std": np.ones(165),
            },
            "does not fit the model",
        ),
    ],
)
def test_damaged_stats_are_refused(demo_copy, tmp_path, stats, message):
    import shutil

    folder = Path(shutil.copytree(demo_copy, tmp_path / "r"))
    if isinstance(stats, bytes):
        (folder / "stats.npz").write_bytes(stats)
    else:
        np.savez(folder / "stats.npz", **stats)
    with pytest.raises(InputFileError, match=message):
        Refiner.load(folder)


def test_a_name_too_long_is_no_refiner_folder(tmp_path):
    with pytest.raises(InputFileError, match="no refiner folder"):
        read_refiner_config(tmp_path / ("r" * 300))


# ---- which refiner made a result --------------------------------------------------------------------


def _db_like(source: str, *, path=None, takes: int = 10, clips: int = 280):
    from types import SimpleNamespace

    return SimpleNamespace(
        path=path,
        meta={"build": {"source": source}},
        take_names=[f"t{i}" for i in range(takes)],
        n_clips=clips,
        label="",
    )


@pytest.mark.parametrize(
    "source, takes, clips, expected",
    [
        ("demo (seed 0, 20 min)", 10, 280, True),
        ("demo (seed 0, 2 min)", 1, 28, True),  # the same generated speaker, shorter
        ("demo (seed 1, 20 min)", 10, 280, False),
        ("/data/zeggs", 10, 280, False),
    ],
)
def test_trained_on_the_demo_speaker(source, takes, clips, expected):
    from gesturekit.refine import refiner_for, trained_on
    from gesturekit.refine.folder import read_refiner_config

    config = read_refiner_config(default_refiner_path())
    db = _db_like(source, takes=takes, clips=clips)
    assert trained_on(config, db) is expected
    assert refiner_for(db) == (default_refiner_path().resolve() if expected else None)


def test_recorded_databases_match_by_folder_or_by_source_takes_and_clips(tmp_path):
    from gesturekit.refine import trained_on

    config = {"database": {"path": str(tmp_path / "db"), "source": "/data/zeggs", "takes": 3, "clips": 40}}
    assert trained_on(config, _db_like("", path=tmp_path / "db"))
    assert trained_on(config, _db_like("/data/zeggs", path=tmp_path / "copy", takes=3, clips=40))
    assert not trained_on(config, _db_like("/data/zeggs", path=tmp_path / "copy", takes=3, clips=41))
    assert not trained_on(config, _db_like("", path=tmp_path / "other"))


@pytest.mark.slow
def test_a_result_records_its_refiner_and_another_database_is_warned(tiny, tmp_path):
    import hashlib
    import warnings

    from gesturekit.errors import GestureKitWarning
    from gesturekit.synthesis import synthesize

    db, out = tiny
    audio = make_take(4.0, seed=5, name="q").audio
    with warnings.catch_warnings():
        warnings.simplefilter("error", GestureKitWarning)  # its own database: no warning
        res = synthesize(audio, db=db, refiner=open_refiner(out))
    meta = json.loads(json.dumps(res.metadata()))
    assert meta["refined"] is True
    assert meta["refiner"]["path"] == str(Path(out).resolve())
    assert meta["refiner"]["generator_sha256"] == hashlib.sha256((out / "generator.pt").read_bytes()).hexdigest()
    assert meta["refiner"]["trained_on"]["path"] == str(db.path)
    assert synthesize(audio, db=db).metadata()["refiner"] is None

    other = MatchingDatabase.build([make_take(8.0, seed=9, name="c")], config=BuildConfig(store_audio=False))
    other.save(tmp_path / "other")
    other = MatchingDatabase.load(tmp_path / "other")
    with pytest.warns(GestureKitWarning, match=r"refiner .* was trained on .*, not on"):
        res = synthesize(audio, db=other, refiner=open_refiner(out))
    assert res.metadata()["refiner"]["trained_on"]["path"] == str(db.path)


def test_the_command_line_applies_a_refiner_trained_on_the_database_unless_told_otherwise(capsys):
    from gesturekit.cli import _refiner_choice

    demo, other = _db_like("demo (seed 0, 20 min)"), _db_like("/data/zeggs")
    assert _refiner_choice(None, demo) == default_refiner_path().resolve()
    assert "trained on this database" in capsys.readouterr().out
    assert _refiner_choice("none", demo) is None
    assert _refiner_choice(None, other) is None
    assert _refiner_choice("demo", other) == "demo"  # named: applied (with the warning at synthesis)
