"""Bad-input suite: control strings and files, time ranges, database folders, Habibie npz files,
refiner folders and numeric options. Each case runs the command line and expects a clean refusal:
exit 2, the file or option named, the problem stated, no traceback, nothing changed."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from gesturekit.control import ATTRIBUTE_NAMES
from tests.badinput import assert_refused, run_cli, snapshot

DEMO_REFINER = Path(__file__).resolve().parents[2] / "gesturekit" / "assets" / "demo-refiner"


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    """A 0.5-minute demo database and a 2 s speech file, made once for the module."""
    from gesturekit.demo import build_demo_database

    root = tmp_path_factory.mktemp("badcfg")
    build_demo_database(root / "db", minutes=0.5)
    t = np.arange(32000) / 16000
    sf.write(root / "speech.wav", (0.3 * np.sin(2 * np.pi * 220 * t)).astype(np.float32), 16000)
    return root


@pytest.fixture
def work(base, tmp_path) -> Path:
    """A per-test copy of the database and the speech, free to break."""
    shutil.copytree(base / "db", tmp_path / "db")
    shutil.copy(base / "speech.wav", tmp_path / "speech.wav")
    return tmp_path


def _synth(work: Path, *extra: str):
    return run_cli("synthesize", work / "speech.wav", "--db", work / "db", "--out", work / "out", *extra)


# ---- control strings ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "text, problem",
    [
        ("1..2-3:left_hand=high", "START-END"),
        ("nan-3:left_hand=high", "START-END"),
        ("0-inf:left_hand=high", "START-END"),
        ("1e400-2:left_hand=high", "START-END"),
        ("3-1:left_hand=high", "end must be after start"),
        ("2-2:left_hand=high", "end must be after start"),
        ("-1-2:left_hand=high", "START-END"),
        ("0-1:left_hand=sideways", "takes low or high"),
        ("0-1:" + "+".join(["left_hand=high"] * 30), "twice"),
        (",".join(f"{i}-{i + 1}:left_hand=high" for i in range(20)) + ",20-21:bogus=1", "unknown control"),
    ],
)
def test_control_string_refused(work, text, problem):
    before = snapshot(work)
    run = _synth(work, f"--control={text}")  # "=": a value starting with "-" is not an option
    assert_refused(run, names="--control", problem=problem, before=before)


def test_long_valid_control_string_is_not_taken_for_a_path(work):
    """A 300-character control string is parsed as a track (no "File name too long"): the run
    goes on to the next check, the database, and stops there."""
    from gesturekit.cli import _control_from_arg
    from gesturekit.control import parse_control

    text = ",".join(f"{i}-{i + 1}:left_hand=high+speed=slow" for i in range(12))
    assert len(text) > 255
    assert _control_from_arg(text) == parse_control(text).to_text()
    before = snapshot(work)
    run = run_cli("synthesize", work / "speech.wav", "--db", work / "no-db", "--out", work / "out", "--control", text)
    assert_refused(run, names=work / "no-db", problem="no database folder", before=before)


# ---- control files ---------------------------------------------------------------------------
def test_missing_control_file_is_named_as_a_file(work):
    before = snapshot(work)
    run = _synth(work, "--control", work / "controls.csv")
    assert_refused(run, names=work / "controls.csv", problem="control file not found", before=before)


@pytest.mark.parametrize(
    "name, content, problem",
    [
        ("c.csv", "start_s,end_s,constraint\n0,1,left_hand=h\xe9\n".encode("latin-1"), "UTF-8"),
        ("c.json", b"42", "list"),
        ("c.json", b'"0-1:left_hand=high"', "list"),
        ("c.json", b"[1, 2]", "row 1"),
        ("c.json", b'[{"start_s": 0, "end_s": 1}]', "constraint"),
        ("c.json", b'{"segments": 5}', "list"),
        ("c.json", b'[{"start_s": "nan", "end_s": 1, "constraint": "left_hand=high"}]', "finite"),
        ("c.csv", b"start_s,constraint\n0,left_hand=high\n", "end_s"),
        ("c.csv", b"a;b;c\n1;2;3\n", "start_s"),
    ],
)
def test_control_file_refused(work, name, content, problem):
    f = work / name
    f.write_bytes(content)
    before = snapshot(work)
    run = _synth(work, "--control", f)
    assert_refused(run, names=f, problem=problem, before=before)


# ---- time ranges: --exclude-range and --holdout ------------------------------------------------
@pytest.mark.parametrize(
    "text, problem",
    [
        ("demo0_000:1..2-3", "TAKE:START-END"),
        ("demo0_000:nan-3", "TAKE:START-END"),
        ("demo0_000:0-inf", "TAKE:START-END"),
        ("demo0_000:3-1", "end must be after start"),
        ("demo0_000:-1-2", "TAKE:START-END"),
    ],
)
def test_exclude_range_refused(work, text, problem):
    before = snapshot(work)
    run = _synth(work, "--exclude-range", text)
    assert_refused(run, names="--exclude-range", problem=problem, before=before)


@pytest.mark.parametrize(
    "text, problem",
    [
        ("demo0_000:1..2-3", "TAKE:START-END"),
        ("demo0_000:nan-3", "TAKE:START-END"),
        ("demo0_000:5-2", "end must be after start"),
    ],
)
def test_holdout_refused(work, text, problem):
    before = snapshot(work)
    run = run_cli("evaluate", "--db", work / "db", "--holdout", text, "--out", work / "ev")
    assert_refused(run, names="--holdout", problem=problem, before=before)
    run = run_cli("stimuli", "--db", work / "db", "--holdout", text, "--out", work / "st")
    assert_refused(run, names="--holdout", problem=problem, before=before)


# ---- database folders --------------------------------------------------------------------------
def _edit_json(db: Path, edit):
    meta = json.loads((db / "database.json").read_text())
    meta = edit(meta)
    (db / "database.json").write_text(json.dumps(meta))


def _truncate(f: Path, keep: float = 0.5):
    data = f.read_bytes()
    f.write_bytes(data[: int(len(data) * keep)])


def _pickled_stats(db: Path):
    with np.load(db / "stats.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["F_mean"] = np.array([object(), None], dtype=object)
    np.savez(db / "stats.npz", **arrays)


def _zero_clips(db: Path):
    for k in ("F", "P", "G", "A", "valid", "attributes", "pose_track", "clip_take", "clip_start"):
        a = np.load(db / f"{k}.npy")
        np.save(db / f"{k}.npy", a[:0])


def _del(key):
    def edit(m):
        del m[key]
        return m

    return edit


def _set(path, value):
    def edit(m):
        d = m
        for k in path[:-1]:
            d = d[k]
        d[path[-1]] = value
        return m

    return edit


def _clip_take_beyond(db: Path):
    ct = np.load(db / "clip_take.npy")
    ct[-1] = 99
    np.save(db / "clip_take.npy", ct)


def _clip_start_beyond(db: Path):
    cs = np.load(db / "clip_start.npy")
    cs[0] = 10_000
    np.save(db / "clip_start.npy", cs)


def _negative_start(db: Path):
    cs = np.load(db / "clip_start.npy")
    cs[0] = -5
    np.save(db / "clip_start.npy", cs)


def _short_clips(db: Path):
    np.save(db / "G.npy", np.load(db / "G.npy")[:, :32])


def _float_clip_take(db: Path):
    np.save(db / "clip_take.npy", np.load(db / "clip_take.npy").astype(np.float32))


def _stats_wrong_shape(db: Path):
    with np.load(db / "stats.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["P_std"] = arrays["P_std"][:3]
    np.savez(db / "stats.npz", **arrays)


def _stats_is_dir(db: Path):
    (db / "stats.npz").unlink()
    (db / "stats.npz").mkdir()


@pytest.mark.parametrize(
    "breakage, problem",
    [
        (lambda db: (db / "stats.npz").unlink(), "stats.npz is missing"),
        (lambda db: _truncate(db / "stats.npz"), "stats.npz"),
        (_pickled_stats, ("object", "pickle")),
        (_stats_wrong_shape, "P_std"),
        (_stats_is_dir, "stats.npz"),
        (lambda db: (db / "database.json").write_text("[]"), "not a gesturekit"),
        (lambda db: _edit_json(db, _del("takes")), "takes"),
        (lambda db: _edit_json(db, _del("build")), "build"),
        (lambda db: _edit_json(db, _del("thresholds")), "thresholds"),
        (lambda db: _edit_json(db, _set(["thresholds", "hand_speed"], "fast")), "hand_speed"),
        (lambda db: _edit_json(db, lambda m: {**m, "thresholds": {ATTRIBUTE_NAMES[0]: [0, 1]}}), "thresholds"),
        (lambda db: _edit_json(db, _set(["takes"], {"a": 1})), "takes"),
        (lambda db: _edit_json(db, _set(["takes", 0, "n_frames"], "many")), "n_frames"),
        (lambda db: _edit_json(db, _set(["build", "clip_frames"], 0)), "clip_frames"),
        (lambda db: _edit_json(db, _set(["counts", "clips"], 3)), "clips"),
        (_zero_clips, "no clips"),
        (_clip_take_beyond, "clip_take"),
        (_clip_start_beyond, "clip_start"),
        (_negative_start, "clip_start"),
        (_short_clips, "G.npy"),
        (_float_clip_take, "clip_take"),
        (lambda db: _truncate(db / "F.npy", 0.9), "F.npy"),
        (lambda db: (db / "database.json").write_bytes(b"\xff\xfe{}"), "database.json"),
    ],
)
def test_database_refused(work, breakage, problem):
    db = work / "db"
    breakage(db)
    before = snapshot(work)
    run = run_cli("info", db)
    assert_refused(run, names=db, problem=problem, before=before)


def test_broken_database_refused_by_synthesize(work):
    db = work / "db"
    _clip_take_beyond(db)
    before = snapshot(work)
    assert_refused(_synth(work), names=db, problem="clip_take", before=before)


# ---- Habibie et al. 2021 npz files ------------------------------------------------------------
def _habibie_npz(f: Path, seconds: float = 6.0):
    n, s = int(seconds * 15), int(seconds * 16000)
    rng = np.random.default_rng(0)
    np.savez(
        f,
        wav=(0.1 * rng.standard_normal((1, s))).astype(np.float32),
        body=(0.1 * rng.standard_normal((1, n, 165))).astype(np.float32),
    )


def _truncated_npz(folder: Path) -> Path:
    f = folder / "speaker.npz"
    _habibie_npz(f)
    _truncate(f, 0.6)
    return f


def _object_npz(folder: Path) -> Path:
    f = folder / "speaker.npz"
    np.savez(f, wav=np.zeros((1, 16000), np.float32), body=np.array([[object()]], dtype=object))
    return f


def _object_wav_npz(folder: Path) -> Path:
    f = folder / "speaker.npz"
    np.savez(f, wav=np.array([None, 1], dtype=object), body=np.zeros((1, 60, 165), np.float32))
    return f


def _not_zip_npz(folder: Path) -> Path:
    f = folder / "speaker.npz"
    f.write_bytes(b"PK\x03\x04 this is not really a zip archive")
    return f


@pytest.mark.parametrize(
    "make, problem",
    [
        (_truncated_npz, ("npz", "zip", "truncated")),
        (_object_npz, ("object", "pickle")),
        (_object_wav_npz, ("object", "pickle")),
        (_not_zip_npz, ("npz", "zip")),
    ],
)
@pytest.mark.parametrize("kind", ["auto", "habibie2021"])
def test_habibie_npz_refused(tmp_path, make, problem, kind):
    folder = tmp_path / "takes"
    folder.mkdir()
    f = make(folder)
    out = tmp_path / "db"
    before = snapshot(tmp_path)
    run = run_cli("build-db", folder, "--kind", kind, "--out", out)
    assert_refused(run, names=f, problem=problem, before=before)


# ---- refiner folders ---------------------------------------------------------------------------
def _refiner_json(ref: Path, edit):
    cfg = json.loads((ref / "config.json").read_text())
    (ref / "config.json").write_text(json.dumps(edit(cfg)))


@pytest.mark.parametrize(
    "breakage, problem",
    [
        (lambda r: _refiner_json(r, lambda c: {**c, "files": list(c["files"])}), "files"),
        (lambda r: _refiner_json(r, lambda c: {**c, "files": {"generator.pt": 5}}), "files"),
        (lambda r: _refiner_json(r, lambda c: {**c, "model": [1, 2]}), "model"),
        (lambda r: _refiner_json(r, lambda c: {**c, "model": {**c["model"], "window": "wide"}}), "window"),
        (lambda r: _refiner_json(r, lambda c: {**c, "layout": "x"}), "layout"),
        (lambda r: _refiner_json(r, lambda c: {**c, "iteration": -3}), "iteration"),
        (lambda r: (r / "config.json").write_text("[]"), "config.json"),
        (lambda r: _truncate(r / "stats.npz"), "stats.npz"),
        (lambda r: (r / "stats.npz").unlink(), "stats.npz"),
        (lambda r: _truncate(r / "generator.pt"), "generator.pt"),
    ],
)
def test_refiner_refused(work, breakage, problem):
    ref = work / "refiner"
    shutil.copytree(DEMO_REFINER, ref)
    breakage(ref)
    before = snapshot(work)
    run = _synth(work, "--refiner", ref)
    assert_refused(run, names=ref, problem=problem, before=before)


def test_corrupt_generator_with_matching_hash_refused(work):
    """A damaged weights file whose hash was written into config.json is still refused cleanly."""
    from gesturekit.refine.infer import file_sha256

    ref = work / "refiner"
    shutil.copytree(DEMO_REFINER, ref)
    _truncate(ref / "generator.pt")
    _refiner_json(ref, lambda c: {**c, "files": {**c["files"], "generator.pt": file_sha256(ref / "generator.pt")}})
    before = snapshot(work)
    run = _synth(work, "--refiner", ref)
    assert_refused(run, names=ref, problem="generator.pt", before=before)


# ---- numeric options ---------------------------------------------------------------------------
@pytest.mark.parametrize("minutes", ["nan", "inf", "0", "-1"])
def test_demo_minutes_refused(tmp_path, minutes):
    out = tmp_path / "db"
    before = snapshot(tmp_path)
    run = run_cli("build-db", "--demo", "--minutes", minutes, "--out", out)
    assert_refused(run, names="--minutes", problem="positive", before=before)


@pytest.mark.parametrize("fps", ["nan", "-30", "0", "inf"])
def test_positions_fps_refused(tmp_path, fps):
    folder = tmp_path / "takes"
    folder.mkdir()
    np.save(folder / "t.npy", np.zeros((60, 55, 3), np.float32))
    sf.write(folder / "t.wav", np.zeros(64000, np.float32), 16000)
    before = snapshot(tmp_path)
    run = run_cli(
        "build-db", folder, "--kind", "positions", "--joint-map", "zeggs", "--fps", fps, "--out", tmp_path / "db"
    )
    assert_refused(run, names="--fps", problem="positive", before=before)


# ---- text over 255 characters where a file may be named ----------------------------------------
def test_speech_name_too_long_is_one_message(work):
    f = work / ("a" * 300 + ".wav")
    before = snapshot(work)
    run = run_cli("synthesize", f, "--db", work / "db", "--out", work / "out")
    assert_refused(run, names=f, problem=("too long", "not found", "no such"), before=before)


def test_joint_map_text_too_long_is_not_a_file(tmp_path):
    folder = tmp_path / "takes"
    folder.mkdir()
    np.save(folder / "t.npy", np.zeros((60, 55, 3), np.float32))
    sf.write(folder / "t.wav", np.zeros(64000, np.float32), 16000)
    spec = "j" * 300
    before = snapshot(tmp_path)
    run = run_cli(
        "build-db", folder, "--kind", "positions", "--joint-map", spec, "--fps", "30", "--out", tmp_path / "db"
    )
    assert_refused(run, names=spec, problem="joint map file not found", before=before)


@pytest.mark.parametrize(
    "option, value, problem",
    [("--beat-sigma", "nan", "positive"), ("--beat-sigma", "inf", "positive"), ("--beat-sigma", "0", "positive")],
)
def test_evaluate_numbers_refused(work, option, value, problem):
    before = snapshot(work)
    run = run_cli("evaluate", "--db", work / "db", "--holdout", "demo0_000:1-9", option, value, "--out", work / "ev")
    assert_refused(run, names=option, problem=problem, before=before)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_stimuli_loudness_refused(work, value):
    before = snapshot(work)
    run = run_cli(
        "stimuli",
        "--db",
        work / "db",
        "--holdout",
        "demo0_000:1-9",
        "--systems",
        "gt",
        f"--loudness={value}",
        "--out",
        work / "st",
    )
    assert_refused(run, names="--loudness", problem="finite", before=before)
