import json
import os
import warnings

import numpy as np
import pytest

from gesturekit.control import ATTRIBUTE_NAMES
from gesturekit.database import BuildConfig, MatchingDatabase, take_features
from gesturekit.errors import ConfigError, DatabaseError, GestureKitWarning, OutputError, collect_warnings
from gesturekit.features import LAYOUT
from tests.conftest import make_take


@pytest.fixture(scope="module")
def takes():
    return [make_take(20.0, seed=1, name="a"), make_take(13.0, seed=2, name="b")]


@pytest.fixture(scope="module")
def db(takes):
    return MatchingDatabase.build(takes, config=BuildConfig(overlap_stride=16))


def test_clip_counts_and_shapes(db, takes):
    # 20 s -> 300 frames -> 4 clips; 13 s -> 195 frames -> 3 clips
    assert db.n_clips == 7
    assert db.F.shape == (7, 64, 112) and db.P.shape == (7, 64, 96) and db.G.shape == (7, 64, 165)
    assert db.A.shape == (7, 64, 28) and db.valid.shape == (7, 64)
    assert db.attributes.shape == (7, 64, len(ATTRIBUTE_NAMES))
    assert db.pose_track.shape == (7, 70, 24)
    assert list(db.clip_take) == [0, 0, 0, 0, 1, 1, 1]
    assert list(db.clip_start) == [0, 64, 128, 192, 0, 64, 128]
    # overlapping cut: starts 0,16,..., up to n-64
    assert list(db.overlap["clip_start"][db.overlap["clip_take"] == 0]) == list(range(0, 300 - 64 + 1, 16))


def test_clips_are_slices_of_whole_take_features(db, takes):
    tf = take_features(takes[0])
    # G is the take's positions, P and F its z-scored features computed on the whole take
    np.testing.assert_array_equal(db.G[1], tf.positions[64:128].reshape(64, -1))
    np.testing.assert_allclose(db.zscore("P").invert(db.P[1]), tf.p[64:128], atol=1e-5)
    np.testing.assert_allclose(db.zscore("F").invert(db.F[0]), tf.f[0:64], atol=1e-3)
    # look-ahead at a clip's last frame reads the next clip's real frames, not padding
    last = db.zscore("F").invert(db.F[0, 63])
    np.testing.assert_allclose(last[-14:], tf.m[63 + 14], atol=1e-3)
    assert db.valid[0].all()
    np.testing.assert_array_equal(db.pose_track[0].reshape(70, 8, 3)[66], tf.positions[66][LAYOUT_INDICES()])


def LAYOUT_INDICES():
    from gesturekit.skeleton import POSE_FEATURE_INDICES

    return POSE_FEATURE_INDICES


def test_padding_frames_are_not_valid(db, takes):
    # take a: 300 frames; frames >= 300-14 need padding; clip 3 covers 192..255: all valid
    assert db.valid[3].all()
    tf = take_features(takes[1])  # 195 frames, clip 2 covers 128..191; frames >= 181 invalid
    assert tf.valid.sum() == 195 - 14
    assert not db.valid[6, 181 - 128 :].any() and db.valid[6, : 181 - 128].all()


def test_zscore_statistics_are_of_valid_frames(db, takes):
    p = np.concatenate([take_features(t).p[take_features(t).valid] for t in takes])
    np.testing.assert_allclose(db.stats["P_mean"], p.mean(0), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(db.stats["P_std"], p.std(0), rtol=1e-4)


# every array under a readable name, with the paper's letter as an alias where it has one
ARRAY_PROPERTIES = {
    "audio_features": "F",
    "pose_features": "P",
    "poses": "G",
    "cgan_audio_features": "A",
    "valid": None,
    "attributes": None,
    "pose_track": None,
    "clip_take": None,
    "clip_start": None,
}


@pytest.mark.parametrize("name,letter", ARRAY_PROPERTIES.items())
def test_arrays_are_documented_properties_and_letters_are_aliases(db, name, letter):
    # properties (not a __getattr__) are what IDEs, type checkers and help() can see
    prop = vars(MatchingDatabase)[name]
    assert isinstance(prop, property) and prop.__doc__ and "shape (M," in prop.__doc__
    key = letter or name
    assert getattr(db, name) is db.arrays[key]
    if letter is not None:
        assert isinstance(vars(MatchingDatabase)[letter], property)
        assert getattr(db, letter) is getattr(db, name)


def test_unknown_attribute_is_an_attribute_error(db):
    assert "__getattr__" not in vars(MatchingDatabase)
    with pytest.raises(AttributeError):
        db.overlap_stride  # noqa: B018  (a build option, not an attribute of the database)
    assert not hasattr(db, "stats_F")


def test_thresholds_are_percentiles_of_clip_frames(db):
    h = db.attribute("left_hand_height").ravel()
    lo, hi = db.thresholds["left_hand_height"]
    assert lo == pytest.approx(np.percentile(h, 15), rel=1e-5)
    assert hi == pytest.approx(np.percentile(h, 85), rel=1e-5)


def test_save_load_round_trip(db, tmp_path):
    path = db.save(tmp_path / "db")
    loaded = MatchingDatabase.load(path)
    for k in ("F", "P", "G", "A", "valid", "attributes", "pose_track", "clip_take", "clip_start"):
        np.testing.assert_array_equal(np.asarray(getattr(loaded, k)), getattr(db, k))
        if k in ("F", "P", "G"):
            assert isinstance(getattr(loaded, k), np.memmap)
    np.testing.assert_array_equal(loaded.overlap["G"], db.overlap["G"])
    assert loaded.thresholds == db.thresholds
    np.testing.assert_array_equal(loaded.take_audio("b"), db.take_audio("b"))
    table = loaded.clips_table()
    assert list(table.columns) == ["clip", "take", "take_index", "start_frame", "start_s", "end_s"]
    assert table.loc[5, "take"] == "b" and table.loc[5, "start_s"] == pytest.approx(64 / 15)
    text = loaded.summary_text()
    assert "clips      7 x 64 frames" in text and "audio f 112" in text


def test_audio_is_kept_and_segments_align(db, takes):
    a = db.take_audio("a")
    np.testing.assert_allclose(a[:16000], takes[0].audio[:16000], atol=1 / 32767)
    seg = db.segment_audio(1, 8, 8)  # take a, frames 72..80
    s0 = round(72 * 16000 / 15)
    np.testing.assert_array_equal(seg, a[s0 : s0 + len(seg)])
    assert len(seg) == pytest.approx(8 * 16000 / 15, abs=1)


def test_refuses_to_overwrite(db, tmp_path):
    db.save(tmp_path / "db")
    with pytest.raises(OutputError, match="already exists"):
        db.save(tmp_path / "db")
    db.save(tmp_path / "db", overwrite=True)
    assert MatchingDatabase.load(tmp_path / "db").n_clips == 7
    assert sorted(os.listdir(tmp_path)) == ["db"]  # no temporary or old folders left


def test_failed_save_leaves_old_database_intact(db, tmp_path, monkeypatch):
    db.save(tmp_path / "db")
    calls = {"n": 0}
    real = np.save

    def failing(*a, **k):
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError("disk full")
        return real(*a, **k)

    monkeypatch.setattr(np, "save", failing)
    with pytest.raises(OutputError, match="disk full"):
        db.save(tmp_path / "db", overwrite=True)
    monkeypatch.undo()
    assert sorted(os.listdir(tmp_path)) == ["db"]
    assert MatchingDatabase.load(tmp_path / "db").n_clips == 7


def test_load_checks_format_and_layout(db, tmp_path):
    path = db.save(tmp_path / "db")
    meta = json.loads((path / "database.json").read_text())
    meta["format_version"] = 999
    (path / "database.json").write_text(json.dumps(meta))
    with pytest.raises(DatabaseError, match="format version 999"):
        MatchingDatabase.load(path)
    meta["format_version"] = 1
    meta["layout"]["n_mfcc"] = 20
    (path / "database.json").write_text(json.dumps(meta))
    with pytest.raises(DatabaseError, match="feature layout"):
        MatchingDatabase.load(path)
    with pytest.raises(DatabaseError, match="no database folder"):
        MatchingDatabase.load(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatabaseError, match="database.json is missing"):
        MatchingDatabase.load(tmp_path / "empty")


def test_missing_array_is_reported(db, tmp_path):
    path = db.save(tmp_path / "db")
    (path / "P.npy").unlink()
    with pytest.raises(DatabaseError, match="P.npy is missing"):
        MatchingDatabase.load(path)


def test_length_mismatch_is_trimmed_with_warning():
    take = make_take(10.0, seed=3)
    from gesturekit.motion import Take

    short_audio = Take(take.name, take.motion, take.audio[: 16000 * 8], take.sources)
    with pytest.warns(GestureKitWarning, match=r"trimmed the motion by 2.00 s to 8.00 s"):
        tf = take_features(short_audio)
    assert tf.n_frames == 120
    # inside collect_warnings (the app's build page), the same message is collected instead
    with warnings.catch_warnings():
        warnings.simplefilter("error", GestureKitWarning)
        with collect_warnings() as notes:
            take_features(short_audio)
    assert len(notes) == 1 and "trimmed the motion by 2.00 s to 8.00 s" in notes[0]


def test_exclusion_mask(db):
    m = db.exclusion_mask(takes=["b"])
    assert m[4:].all() and not m[:4].any()
    r = db.exclusion_mask(ranges=[("a", 5.0, 6.0)])  # frames 75..89 of take a (clip 1 starts at 64)
    assert r.sum() == 15 and r[1, 75 - 64 : 90 - 64].all()
    with pytest.raises(ConfigError, match="no take named"):
        db.exclusion_mask(takes=["zzz"])


def test_unique_take_names_and_too_short_takes():
    with pytest.raises(ConfigError, match="unique"):
        MatchingDatabase.build([make_take(6.0, name="x"), make_take(6.0, seed=5, name="x")])
    with pytest.raises(ConfigError, match="shorter than one clip"):
        MatchingDatabase.build([make_take(3.0, name="x")])


def test_query_features_use_database_statistics(db, takes):
    fq, aq = db.query_features(takes[0].audio)
    assert fq.shape == (300, 112) and aq.shape == (300, 28)
    np.testing.assert_allclose(fq[:64], db.F[0], atol=1e-4)


# ---- load validates what it reads -------------------------------------------------------------
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_json = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-3, 10**7)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(max_size=4),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3),
    max_leaves=5,
)


@pytest.fixture(scope="module")
def saved(db, tmp_path_factory):
    return db.save(tmp_path_factory.mktemp("validated") / "db")


def _places(meta):
    """Every editable place of database.json: (container, key) pairs, format/layout left alone."""
    out = [(meta, k) for k in meta if k not in ("format", "format_version", "layout")]
    for name in ("build", "thresholds", "counts"):
        out += [(meta[name], k) for k in meta[name]]
    for t in meta["takes"]:
        out += [(t, k) for k in t]
    out.append((meta["takes"], 0))
    return out


@pytest.mark.slow
@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(data=st.data())
def test_damaged_database_json_is_refused_or_consistent(saved, data):
    original = (saved / "database.json").read_text()
    meta = json.loads(original)
    places = _places(meta)
    container, key = places[data.draw(st.integers(0, len(places) - 1), label="place")]
    if data.draw(st.booleans(), label="delete") and isinstance(container, dict):
        del container[key]
    else:
        container[key] = data.draw(_json, label="value")
    (saved / "database.json").write_text(json.dumps(meta))
    try:
        loaded = MatchingDatabase.load(saved)
    except DatabaseError as exc:
        assert exc.path == str(saved)
        return
    finally:
        (saved / "database.json").write_text(original)
    # whatever loads is consistent: every clip inside its take, the tables and thresholds usable
    table = loaded.clips_table()
    frames = {t["name"]: t["n_frames"] for t in loaded.meta["takes"]}
    assert all(row.start_frame + loaded.clip_frames <= frames[row.take] for row in table.itertuples())
    assert set(loaded.thresholds) == set(ATTRIBUTE_NAMES)
    loaded.takes_table()
    assert loaded.summary_text().startswith("database")


def _resave(path, name, array):
    np.save(path / f"{name}.npy", array)


@pytest.mark.parametrize(
    "name, change, message",
    [
        ("clip_take", lambda a: a[::-1].copy(), "does not match the takes"),
        ("clip_take", lambda a: a.astype(np.float64), "must be integers"),
        ("clip_start", lambda a: a[:-1], "clip_start.npy has"),
        ("clip_start", lambda a: a + 10_000, "outside take"),
        ("valid", lambda a: a[:, :10], r"valid.npy has shape"),
        ("pose_track", lambda a: a[:, :64], "pose_track.npy has shape"),
        ("clip_take", lambda a: a[:0], "no clips"),
    ],
)
def test_inconsistent_arrays_are_refused(db, tmp_path, name, change, message):
    path = db.save(tmp_path / "db")
    _resave(path, name, change(np.load(path / f"{name}.npy")))
    with pytest.raises(DatabaseError, match=message):
        MatchingDatabase.load(path)


def test_overlap_cut_is_checked_too(db, tmp_path):
    path = db.save(tmp_path / "db")
    start = np.load(path / "overlap" / "clip_start.npy")
    start[-1] = 10**6
    np.save(path / "overlap" / "clip_start.npy", start)
    with pytest.raises(DatabaseError, match="overlap/clip_start.npy"):
        MatchingDatabase.load(path)


@pytest.mark.parametrize(
    "breakage, message",
    [
        (lambda p: (p / "stats.npz").write_bytes((p / "stats.npz").read_bytes()[:300]), "stats.npz cannot be read"),
        (lambda p: np.savez(p / "stats.npz", F_mean=np.array([None], dtype=object)), "stats.npz cannot be read"),
        (lambda p: np.savez(p / "stats.npz", F_mean=np.zeros(LAYOUT.audio_dim)), "stats.npz lacks F_std"),
        (
            lambda p: np.savez(
                p / "stats.npz",
                **{
                    f"{k}_{s}": np.full(n, np.nan)
                    for k, n in (("F", LAYOUT.audio_dim), ("P", LAYOUT.pose_dim), ("A", LAYOUT.cgan_audio_dim))
                    for s in ("mean", "std")
                },
            ),
            "F_mean must be 112 finite numbers",
        ),
        (lambda p: (p / "audio.npy").write_bytes(b"not an array"), "audio.npy cannot be read"),
        (lambda p: np.save(p / "audio.npy", np.zeros(10, np.int16)), "audio.npy must be int16 samples"),
        (lambda p: ((p / "F.npy").unlink(), (p / "F.npy").mkdir()), "F.npy is a folder, not a regular file"),
        (
            lambda p: (p / "database.json").write_text(
                '{"format": "gesturekit-matching-database", "format_version": 1}'
            ),
            "feature layout",
        ),
    ],
)
def test_damaged_files_are_refused(db, tmp_path, breakage, message):
    path = db.save(tmp_path / "db")
    breakage(path)
    with pytest.raises(DatabaseError, match=message):
        MatchingDatabase.load(path)


def test_a_name_too_long_is_no_database_folder(tmp_path):
    with pytest.raises(DatabaseError, match="no database folder"):
        MatchingDatabase.load(tmp_path / ("d" * 300))


@pytest.mark.parametrize("rng", [("a", float("nan"), 2.0), ("a", 0.0, float("inf")), ("a", 3.0, 1.0), ("a", -1.0, 1.0)])
def test_exclusion_ranges_must_be_finite_and_ordered(rng):
    from gesturekit.database import normalise_exclusions

    with pytest.raises(ConfigError, match="0 <= start < end"):
        normalise_exclusions((), [rng])
    assert normalise_exclusions(("b",), [("a", 0, 1.5)]) == (("b",), (("a", 0.0, 1.5),))
