"""Synthesis: the pipeline, its options and the acceptance items of the command line."""

import hashlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.cli import main
from gesturekit.control import parse_control
from gesturekit.database import MatchingDatabase
from gesturekit.demo import build_demo_database
from gesturekit.errors import ConfigError, GestureKitWarning
from gesturekit.export.result import save_result_bvh, save_result_npz
from gesturekit.motion import Motion
from gesturekit.search.reference import search_reference
from gesturekit.skeleton import joint_index
from gesturekit.synthesis import SynthesisConfig, rest_pose_frame, synthesize, synthesize_batch

LW = joint_index("left_wrist")


@pytest.fixture(scope="module")
def demo_db(tmp_path_factory):
    path = tmp_path_factory.mktemp("demo") / "db"
    build_demo_database(path, minutes=4.0)
    return MatchingDatabase.load(path)


@pytest.fixture(scope="module")
def speech():
    from gesturekit.datasets.synthetic import generate_demo_take

    take, _ = generate_demo_take(seconds=20.0, seed=123, name="query")
    return take.audio


@pytest.mark.slow
@settings(max_examples=12, deadline=None)
@given(st.integers(16000, 16000 * 40))
def test_output_length_is_the_audios_frame_count(demo_db, n_samples):
    rng = np.random.default_rng(n_samples)
    audio = (0.1 * rng.normal(size=n_samples)).astype(np.float32)
    res = synthesize(audio, db=demo_db)
    assert res.n_frames == n_samples * 15 // 16000
    assert res.motion.positions.shape == (res.n_frames, 55, 3)
    assert res.search.n_steps == -(-res.n_frames // 8)


@pytest.mark.slow
def test_sixty_minutes_of_speech(demo_db):
    rng = np.random.default_rng(0)
    t = np.arange(16000 * 60 * 60, dtype=np.float32) / 16000
    audio = (0.2 * np.sin(2 * np.pi * 180 * t) * (np.sin(2 * np.pi * 0.7 * t) > 0)).astype(np.float32)
    audio += (0.01 * rng.normal(size=audio.size)).astype(np.float32)
    res = synthesize(audio, db=demo_db)
    assert res.n_frames == 54000 and res.search.n_steps == 6750


def test_matches_the_reference_search(demo_db, speech):
    cfg = SynthesisConfig(k=1, control="2-8:left_hand=high,10-14:speed=slow", seed=3)
    res = synthesize(speech, db=demo_db, config=cfg)
    from gesturekit.control import step_masks
    from gesturekit.search import SearchConfig

    fq, _ = demo_db.query_features(speech)
    masks, smask = step_masks(
        parse_control(cfg.control), np.asarray(demo_db.attributes), demo_db.thresholds, n_frames=len(fq), segment=8
    )
    ref = search_reference(
        np.asarray(demo_db.P),
        np.asarray(demo_db.F),
        np.asarray(demo_db.valid),
        fq,
        config=SearchConfig(k=1, seed=3),
        masks=masks,
        step_mask_index=smask,
    )
    np.testing.assert_array_equal(res.search.clip, ref.clip)
    np.testing.assert_array_equal(res.search.start, ref.start)
    g = np.asarray(demo_db.G)[ref.frames[:, 0], ref.frames[:, 1]]
    np.testing.assert_array_equal(res.knn_motion.flat(), g)


def test_excluded_takes_and_ranges_are_never_used(demo_db, speech):
    table = demo_db.clips_table()
    take0 = demo_db.take_names[0]
    res = synthesize(speech, db=demo_db, config=SynthesisConfig(exclude_takes=(take0,)))
    used_takes = set(table.loc[np.unique(res.search.frames[:, 0]), "take"])
    assert take0 not in used_takes
    res = synthesize(speech, db=demo_db, config=SynthesisConfig(exclude_ranges=((take0, 0.0, 60.0),)))
    clip, frame = res.search.frames.T
    takes = table["take"].to_numpy()[clip]
    seconds = (table["start_frame"].to_numpy()[clip] + frame) / 15
    assert not np.any((takes == take0) & (seconds < 60.0))
    # without the exclusion the same speech does use that take (so the test can fail)
    res = synthesize(speech, db=demo_db)
    assert take0 in set(table.loc[np.unique(res.search.frames[:, 0]), "take"])


def test_same_seed_gives_byte_identical_npz(demo_db, speech, tmp_path):
    cfg = SynthesisConfig(seed=7, control="0-5:right_hand=high")
    a = save_result_npz(synthesize(speech, db=demo_db, config=cfg), tmp_path / "a.npz")
    b = save_result_npz(synthesize(speech, db=demo_db, config=cfg), tmp_path / "b.npz")
    assert hashlib.sha256(a.read_bytes()).digest() == hashlib.sha256(b.read_bytes()).digest()
    c = synthesize(speech, db=demo_db, config=SynthesisConfig(seed=8, control="0-5:right_hand=high"))
    assert not np.array_equal(c.search.clip, synthesize(speech, db=demo_db, config=cfg).search.clip)


def test_npz_holds_motion_record_and_config(demo_db, speech, tmp_path):
    from gesturekit.export.npz import load_npz

    res = synthesize(speech, db=demo_db, config=SynthesisConfig(blend="offset", control="1-4:width=wide"))
    motion, arrays, config = load_npz(save_result_npz(res, tmp_path / "r.npz"))
    np.testing.assert_array_equal(motion.positions, res.motion.positions)
    np.testing.assert_array_equal(arrays["knn_positions"], res.knn_motion.positions)
    np.testing.assert_array_equal(arrays["search_cand_clip"], res.search.cand_clip)
    assert config["synthesis"]["control"] == "1-4:width=wide" and config["synthesis"]["blend"] == "offset"
    assert SynthesisConfig.from_dict(config["synthesis"]) == res.config


def test_pinning_a_candidate_changes_that_step_only_from_there(demo_db, speech):
    base = synthesize(speech, db=demo_db)
    i = 5
    alt = base.search.cand_clip[i, 3], base.search.cand_start[i, 3]
    pinned = synthesize(speech, db=demo_db, config=SynthesisConfig().with_pin(i, *alt))
    assert (pinned.search.clip[i], pinned.search.start[i]) == alt and pinned.search.pinned[i]
    np.testing.assert_array_equal(pinned.search.clip[:i], base.search.clip[:i])
    np.testing.assert_array_equal(pinned.motion.positions[: i * 8], base.motion.positions[: i * 8])
    assert not np.array_equal(pinned.search.clip[i:], base.search.clip[i:])
    unpinned = synthesize(speech, db=demo_db, config=SynthesisConfig().with_pin(i, *alt).without_pin(i))
    np.testing.assert_array_equal(unpinned.search.clip, base.search.clip)


@pytest.mark.slow
def test_batch_equals_single_runs(demo_db, speech):
    audios = [speech, speech[: 16000 * 7], speech[16000 * 3 :]]
    configs = [SynthesisConfig(), SynthesisConfig(k=2, control="0-3:speed=fast"), SynthesisConfig(seed=4)]
    batch = synthesize_batch(audios, db=demo_db, config=configs)
    for a, c, b in zip(audios, configs, batch):
        single = synthesize(a, db=demo_db, config=c)
        assert single.search.equals(b.search)
        np.testing.assert_array_equal(single.motion.positions, b.motion.positions)


def test_k_changes_the_choice_and_records_the_candidates(demo_db, speech):
    r0 = synthesize(speech, db=demo_db, config=SynthesisConfig(k=0, record=5))
    r2 = synthesize(speech, db=demo_db, config=SynthesisConfig(k=2, record=5))
    assert r0.search.cand_clip.shape[1] == 5
    assert (r2.search.position == 2).all()
    assert r0.search.clip[0] != r2.search.clip[0] or r0.search.start[0] != r2.search.start[0]
    df = r0.search.candidates_frame()
    assert set(df.columns) >= {"clip", "start", "pose_dist", "audio_dist", "pose_rank", "audio_rank", "combined"}
    assert (df.groupby("step").size() == 5).all()


def test_impossible_control_relaxes_with_warning(demo_db, speech):
    # both hands high AND slow AND narrow AND symmetric: no window of the demo satisfies all
    ctl = "0-6:both_hands=high+speed=slow+width=narrow+symmetry=asymmetric"
    with pytest.warns(GestureKitWarning, match="relaxed"):
        res = synthesize(speech, db=demo_db, config=SynthesisConfig(control=ctl))
    assert res.relaxed_steps and max(res.relaxed_steps) * 8 < 6 * 15
    assert res.metadata()["relaxed_steps"] == res.relaxed_steps


def test_rest_init_starts_from_the_rest_frame(demo_db, speech):
    res = synthesize(speech, db=demo_db, config=SynthesisConfig(init="rest"))
    c, f = rest_pose_frame(demo_db)
    np.testing.assert_array_equal(res.search.init_pose, np.asarray(demo_db.P)[c, f])
    assert demo_db.attribute("hand_speed")[c, f] <= demo_db.thresholds["hand_speed"][0]


def test_blend_none_is_the_paper_and_the_default_smooths(demo_db, speech):
    none = synthesize(speech, db=demo_db, config=SynthesisConfig(blend="none"))
    default = synthesize(speech, db=demo_db)
    assert SynthesisConfig().blend == "dead" and default.config.blend == "dead"
    np.testing.assert_array_equal(none.motion.positions, none.knn_motion.positions)  # the hard joins
    np.testing.assert_array_equal(default.knn_motion.positions, none.knn_motion.positions)
    assert not np.array_equal(default.motion.positions, none.motion.positions)
    assert SynthesisConfig().paper_differences(refined=False) == ["blending: dead (paper none)"]
    # a refiner is given the k-NN motion: the blend does not count
    assert SynthesisConfig(refiner_keep_hz=0.0).paper_differences(refined=True) == []


@pytest.mark.parametrize("mode", ["offset", "inertialize", "dead"])
def test_blends_shrink_the_jumps_at_joins(demo_db, speech, mode):
    none = synthesize(speech, db=demo_db, config=SynthesisConfig(blend="none"))
    off = synthesize(speech, db=demo_db, config=SynthesisConfig(blend=mode))
    b = np.arange(8, none.n_frames, 8)

    def join_jerk(m):
        g = m.flat()
        acc = g[b] - 2 * g[b - 1] + g[b - 2]
        return np.linalg.norm(acc, axis=1).mean()

    assert join_jerk(off.motion) < 0.5 * join_jerk(none.motion)
    np.testing.assert_array_equal(off.knn_motion.positions, none.knn_motion.positions)


def test_bad_options_are_config_errors(demo_db, speech):
    with pytest.raises(ConfigError, match="init"):
        SynthesisConfig(init="t-pose")
    with pytest.raises(ConfigError, match="unknown control"):
        SynthesisConfig(control="0-2:elbows=up")
    with pytest.raises(ConfigError, match="no take named"):
        synthesize(speech, db=demo_db, config=SynthesisConfig(exclude_takes=("nope",)))


# ---- acceptance on the real ZEGGS take ----------------------------------------------------------


class _HalfRefiner:
    """A stand-in refiner (the MotionRefiner protocol without provenance): halves the motion."""

    def __init__(self):
        self.checked = []

    def check_database(self, db, /):
        self.checked.append(db)

    def refine_motion(self, motion, audio_features, /):
        assert audio_features.shape == (motion.n_frames, 28)
        return Motion(motion.positions * 0.5, motion.fps)


def test_a_refiner_is_an_object_and_a_folder_is_opened_above(demo_db, speech, tmp_path):
    from gesturekit.refine import open_refiner
    from gesturekit.synthesis import MotionRefiner

    refiner = _HalfRefiner()
    assert isinstance(refiner, MotionRefiner) and open_refiner(refiner) is refiner and open_refiner(None) is None
    cfg = SynthesisConfig(refiner_keep_hz=0)
    res = synthesize(speech[: 16000 * 3], db=demo_db, config=cfg, refiner=refiner)
    assert refiner.checked == [demo_db] and res.refiner is None  # no provenance: nothing recorded
    np.testing.assert_allclose(res.motion.positions, 0.5 * res.knn_motion.positions)
    # a folder given to synthesis itself: a message saying how to open it, before any search
    for folder in (str(tmp_path), tmp_path, "demo"):
        with pytest.raises(ConfigError, match=r"refiner must be a loaded refiner, got .*open_refiner"):
            synthesize(speech[:16000], db=demo_db, refiner=folder)


@pytest.fixture(scope="module")
def zeggs_db(tmp_path_factory):
    from tests.conftest import ZEGGS_BVH

    if not ZEGGS_BVH.is_file():
        pytest.skip(f"ZEGGS take not found at {ZEGGS_BVH}")
    out = tmp_path_factory.mktemp("zeggs") / "db"
    assert main(["build-db", str(ZEGGS_BVH.parent), "--preset", "zeggs", "--out", str(out)]) == 0
    return MatchingDatabase.load(out)


@pytest.fixture
def beat_speech(shared_data):
    p = shared_data / "speech" / "beat_lawrence_0_19_19.wav"
    if not p.is_file():
        pytest.skip(f"{p} not found")
    return p


def test_zeggs_left_hand_high_paper_rule(zeggs_db, beat_speech):
    res = synthesize(beat_speech, db=zeggs_db, config=SynthesisConfig(control="0-1000:left_hand=high"))
    high = res.motion.positions[:, LW, 1] > zeggs_db.thresholds["left_hand_height"][1]
    assert high.mean() >= 0.90
    assert res.relaxed_steps == [] or res.metadata()["relaxed_steps"] == res.relaxed_steps


def test_zeggs_left_hand_high_every_frame_rule(zeggs_db, beat_speech):
    res = synthesize(
        beat_speech, db=zeggs_db, config=SynthesisConfig(control="0-1000:left_hand=high", mask_rule="all", blend="none")
    )
    high = res.motion.positions[:, LW, 1] > zeggs_db.thresholds["left_hand_height"][1]
    relaxed_frames = np.zeros(res.n_frames, bool)
    for i in res.relaxed_steps:
        relaxed_frames[i * 8 : (i + 1) * 8] = True
    assert high[~relaxed_frames].all() and high.mean() == 1.0


def test_zeggs_bvh_export_read_back_independently(zeggs_db, shared_data, tmp_path):
    import bvhio

    speech = shared_data / "speech" / "espeak_en_us.wav"
    res = synthesize(speech, db=zeggs_db, config=SynthesisConfig(control="2-6:right_hand=high"))
    path = save_result_bvh(res, tmp_path / "out.bvh", units="m")
    root = bvhio.readAsHierarchy(str(path))
    names = [j.Name for j, _, _ in root.layout()]
    from gesturekit.skeleton import JOINT_NAMES

    got = np.zeros((res.n_frames, 55, 3))
    for f in range(res.n_frames):
        root.loadPose(f)
        pos = {j.Name: np.asarray(j.PositionWorld) for j, _, _ in root.layout()}
        got[f] = [pos[n] for n in JOINT_NAMES]
    assert set(JOINT_NAMES) <= set(names)
    assert np.abs(got - res.motion.positions).max() < 1e-3


@pytest.mark.slow
def test_cli_synthesize_with_video_and_controls(zeggs_db, shared_data, tmp_path, capsys):
    from gesturekit.export.video import probe_media

    speech = shared_data / "speech" / "espeak_en_us.wav"
    control = tmp_path / "control.csv"
    control.write_text("start_s,end_s,constraint\n0,4,left_hand=low\n4,8,speed=fast+width=wide\n")
    out = tmp_path / "out"
    args = [
        "synthesize",
        str(speech),
        "--db",
        str(zeggs_db.path),
        "--out",
        str(out),
        "--control",
        str(control),
        "--k",
        "1",
        "--seed",
        "3",
        "--video",
    ]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "espeak_en_us.wav: 253 frames" in printed
    import soundfile as sf

    info = probe_media(out / "espeak_en_us.mp4")
    duration = sf.info(speech).duration
    assert info["video"]["codec"] == "h264" and info["audio"]["codec"] == "aac"
    assert abs(info["video"]["duration"] - duration) <= 1 / 15 + 1e-6
    assert abs(info["audio"]["duration"] - duration) < 0.05
    assert main(args) == 2 and "add --force" in capsys.readouterr().err
    from gesturekit.export.npz import load_npz

    _, _, config = load_npz(out / "espeak_en_us.npz")
    assert config["synthesis"]["control"] == "0-4:left_hand=low,4-8:speed=fast+width=wide"
    assert config["synthesis"]["k"] == 1 and config["source"] == "espeak_en_us.wav"


@settings(max_examples=60, deadline=None)
@given(
    k=st.integers(0, 3),
    segment=st.integers(1, 12),
    init=st.sampled_from(["random", "rest"]),
    blend=st.sampled_from(["none", "offset", "inertialize", "dead"]),
    mask_rule=st.sampled_from(["ends", "all"]),
    keep=st.sampled_from([0.0, 1.5, 2.0]),
    refined=st.booleans(),
)
def test_paper_differences_name_exactly_the_settings_that_differ(k, segment, init, blend, mask_rule, keep, refined):
    config = SynthesisConfig(k=k, segment=segment, init=init, blend=blend, mask_rule=mask_rule, refiner_keep_hz=keep)
    notes = config.paper_differences(refined=refined)
    expected = {
        "k = ": k != 0,
        "N = ": segment != 8,
        "initial pose": init != "random",
        "blending": blend != "none" and not refined,
        "control held at": mask_rule != "ends",
        "kept below": refined and keep != 0,
    }
    for text, differs in expected.items():
        assert sum(text in n for n in notes) == int(differs), (text, notes)
    assert len(notes) == sum(expected.values())
    if segment != 8:
        assert f"N = {segment} (paper 8)" in notes


def test_the_paper_search_has_no_differences():
    assert SynthesisConfig(refiner_keep_hz=0.0).paper_differences(refined=True) == []
    assert SynthesisConfig(blend="none").paper_differences(refined=False) == []
    assert (
        SynthesisConfig(blend="none", seed=9, record=3).paper_differences(refined=False) == []
    )  # no effect on the method


# -- one plan, one source of truth for the search's options and the control track ---------------------


def test_a_given_control_is_the_one_searched_and_recorded(demo_db, speech):
    # the config says one control, the argument another: the argument wins, and the result says so
    a, b = "0-20:left_hand=high", "0-20:left_hand=low"
    res = synthesize(speech, db=demo_db, config=SynthesisConfig(control=a), control=b)
    alone = synthesize(speech, db=demo_db, config=SynthesisConfig(control=b))
    assert res.config.control == b and res.control.to_text() == b and res.plan.control.to_text() == b
    assert res.search.equals(alone.search) and res.config == alone.config
    assert not synthesize(speech, db=demo_db, config=SynthesisConfig(control=a)).search.equals(res.search)


def test_the_result_keeps_the_plan_it_searched_with(demo_db, speech):
    from gesturekit.search import plan_search
    from gesturekit.synthesis import search_request

    cfg = SynthesisConfig(k=1, segment=6, init="rest", control="1-5:speed=slow", exclude_takes=(demo_db.take_names[0],))
    res = synthesize(speech, db=demo_db, config=cfg)
    plan = res.plan
    # planned again from the database's own query features (the plain reference)
    again = plan_search(demo_db, demo_db.query_features(speech)[0], search_request(cfg))
    np.testing.assert_array_equal(plan.query, again.query)
    np.testing.assert_array_equal(plan.masks, again.masks)
    np.testing.assert_array_equal(plan.step_mask_index, again.step_mask_index)
    np.testing.assert_array_equal(plan.exclude, again.exclude)
    assert plan.config == again.config == res.search.config and plan.segment == 6
    assert plan.n_steps == res.search.n_steps and plan.n_frames == res.n_frames
    np.testing.assert_array_equal(res.search.init_pose, np.asarray(plan.config.init_pose, np.float32))
    assert plan.mask_at(0) is None and plan.mask_at(3) is not None  # step 3 covers 1.2-1.6 s
    with pytest.raises(ConfigError, match="step must be in"):
        plan.mask_at(plan.n_steps)


@settings(max_examples=40, deadline=None)
@given(
    k=st.integers(0, 5),
    segment=st.integers(1, 16),
    record=st.integers(1, 12),
    seed=st.integers(0, 9),
    rule=st.sampled_from(["ends", "all"]),
    init=st.sampled_from(["random", "rest"]),
    pins=st.dictionaries(st.integers(0, 9), st.tuples(st.integers(0, 9), st.integers(0, 9)), max_size=3),
)
def test_the_search_options_live_in_one_nested_config(k, segment, record, seed, rule, init, pins):
    import dataclasses
    import json

    from gesturekit.search import SearchConfig

    flat = SynthesisConfig(k=k, segment=segment, record=record, seed=seed, mask_rule=rule, init=init, pins=pins)
    nested = SynthesisConfig(
        SearchConfig(k=k, segment=segment, record=record, seed=seed, mask_rule=rule, pins=pins), init=init
    )
    assert flat == nested and flat.search == SearchConfig(
        k=k, segment=segment, record=record, seed=seed, mask_rule=rule, pins=pins
    )
    assert (flat.k, flat.segment, flat.record, flat.seed, flat.mask_rule, flat.pins) == (
        k,
        segment,
        record,
        seed,
        rule,
        flat.search.pins,
    )
    assert dataclasses.replace(flat, k=k + 1).search == dataclasses.replace(flat.search, k=k + 1)
    saved = json.loads(json.dumps(flat.to_dict()))
    # the saved form is the flat one earlier versions wrote (and read), and reads back
    assert set(saved) == {
        "k",
        "segment",
        "record",
        "seed",
        "init",
        "mask_rule",
        "blend",
        "blend_frames",
        "blend_halflife",
        "control",
        "exclude_takes",
        "exclude_ranges",
        "pins",
        "refiner_keep_hz",
    }
    assert SynthesisConfig.from_dict(saved) == flat
    search = {name: saved.pop(name) for name in ("k", "segment", "record", "seed", "mask_rule", "pins")}
    assert SynthesisConfig.from_dict({**saved, "search": search}) == flat
    # a nested search saved under the earlier names reads back too
    search["step"], search["topk"] = search.pop("segment"), search.pop("record")
    assert SynthesisConfig.from_dict({**saved, "search": search}) == flat


def test_a_config_saved_by_an_earlier_version_reads_back():
    saved = {
        "k": 2,
        "step": 6,
        "topk": 7,
        "seed": 5,
        "init": "rest",
        "mask_rule": "all",
        "blend": "offset",
        "blend_frames": 3,
        "control": "0-4.25:both_hands=high",
        "exclude_takes": ["a"],
        "exclude_ranges": [["b", 1.0, 2.5]],
        "pins": {"3": [4, 5]},
        "refiner_keep_hz": 1.5,
    }
    cfg = SynthesisConfig.from_dict(saved)
    assert (cfg.k, cfg.segment, cfg.record, cfg.seed, cfg.init, cfg.mask_rule) == (2, 6, 7, 5, "rest", "all")
    assert cfg.pins == {3: (4, 5)} and cfg.exclude_ranges == (("b", 1.0, 2.5),) and cfg.exclude_takes == ("a",)
    # written back under the current names: N is "segment", the recorded candidates "record"
    renamed = {{"step": "segment", "topk": "record"}.get(name, name): value for name, value in saved.items()}
    renamed["blend_halflife"] = SynthesisConfig().blend_halflife  # saved before it was an option: the default
    assert cfg.control_track.to_text() == "0-4.25:both_hands=high" and cfg.to_dict() == renamed
    assert SynthesisConfig.from_dict(renamed) == cfg
    with pytest.raises(ConfigError, match="unknown synthesis options: nope"):
        SynthesisConfig.from_dict({**saved, "nope": 1})
    with pytest.raises(ConfigError, match="unknown synthesis options: nope"):
        SynthesisConfig(nope=1)
    with pytest.raises(ConfigError, match="init_pose"):
        SynthesisConfig(
            search=__import__("gesturekit.search", fromlist=["SearchConfig"]).SearchConfig(init_pose=(1.0,))
        )


@pytest.mark.slow
def test_zeggs_default_joins_move_like_the_take(zeggs_db, beat_speech):
    from gesturekit.evaluate.metrics import kinematic_magnitudes, mean_jerk

    clips = np.asarray(zeggs_db.G, np.float32).reshape(zeggs_db.n_clips, -1, 55, 3)
    own = np.concatenate([kinematic_magnitudes(c, fps=zeggs_db.fps, order=3) for c in clips]).mean()
    hard = synthesize(beat_speech, db=zeggs_db, config=SynthesisConfig(blend="none"))
    smooth = synthesize(beat_speech, db=zeggs_db)
    ratio_hard = mean_jerk(hard.motion.positions, fps=zeggs_db.fps) / own
    ratio = mean_jerk(smooth.motion.positions, fps=zeggs_db.fps) / own
    assert ratio_hard > 1.8 and 0.7 <= ratio <= 1.3, (ratio_hard, ratio)
    np.testing.assert_array_equal(smooth.knn_motion.positions, hard.knn_motion.positions)


def test_zeggs_with_the_scan_on_a_torch_device_gives_the_same_motion(zeggs_db, beat_speech):
    # recorded motion (consecutive frames nearly equal: clips left open for the exact look) and
    # recorded speech, through the device's per-clip reduction (torch's CPU device stands in for a GPU)
    pytest.importorskip("torch")
    from gesturekit.synthesis import synthesizer_for

    cfg = SynthesisConfig(k=2, seed=4, control="2-9:left_hand=high,12-20:speed=slow")
    here = synthesize(beat_speech, db=zeggs_db, config=cfg)
    there = synthesize(beat_speech, db=zeggs_db, config=cfg, search_device="cpu:0")
    for name, x in here.search.array_fields().items():
        assert np.array_equal(x, there.search.array_fields()[name], equal_nan=x.dtype.kind == "f"), name
    np.testing.assert_array_equal(here.motion.positions, there.motion.positions)
    index = synthesizer_for(zeggs_db, search_device="cpu:0").index
    M, T = zeggs_db.valid.shape
    q = np.asarray(zeggs_db.P[M // 2, T // 2], np.float32)[None]
    bias = np.where(zeggs_db.valid.ravel(), index._np32, np.float32(np.inf))
    opened = index._scan(q, [bias], np.asarray(zeggs_db.F[0, :1], np.float32))[4][0][0]
    # a step's query is a database frame (the last pose chosen): its own clip's least distance may be
    # an exact zero, so that clip's row comes back open and is settled exactly
    assert M // 2 in opened


def test_zeggs_search_matches_the_reference_on_recorded_motion(zeggs_db, beat_speech):
    # recorded motion is where the 8-bit bound leaves most clips open (consecutive frames nearly
    # equal): the scan's float32 passes over those clips, narrowed by each clip's least start,
    # must choose what the plain float64 loop chooses, step by step, with controls and k > 0;
    # and so must the scan of the frame copy, which the take's features allow
    from gesturekit.control import step_masks
    from gesturekit.search import SearchConfig, SearchIndex
    from gesturekit.search.reduced import clip_bounds, compiled_reduced, quantise_query, reduce_pose
    from gesturekit.synthesis.types import load_speech

    P, F, valid = (np.asarray(a) for a in (zeggs_db.P, zeggs_db.F, zeggs_db.valid))
    fq, _ = zeggs_db.query_features(load_speech(beat_speech)[0])
    fq = fq[: 8 * 40]
    masks, smask = step_masks(
        parse_control("1-8:left_hand=high,10-16:speed=slow"),
        np.asarray(zeggs_db.attributes),
        zeggs_db.thresholds,
        n_frames=len(fq),
        segment=8,
    )
    M, T, D = P.shape
    init = P[M // 3, 5].copy()
    # the property this test needs of its input: most clips open, more of them than the scan asks for ahead
    red, codes = reduce_pose(P), quantise_query(init)
    k = compiled_reduced()
    est = np.array(
        [
            [
                k.reduced_estimate(
                    (red.codes, red.coef, red.kappa, red.centre, red.stats), c, s, codes.codes, np.float32(codes.scale)
                )
                for s in range(T)
            ]
            for c in range(M)
        ],
        np.float64,
    )
    centred = ((init.astype(np.float64) - red.centre) ** 2).sum(axis=1)
    bound = clip_bounds(red.stats, centred, codes, D)
    open_ = np.count_nonzero(est <= (est.min(axis=1) + 2 * bound)[:, None], axis=1) > 1
    assert open_.sum() > k.PREFETCH_AHEAD and open_.mean() > 0.5, (open_.sum(), M)
    cfg = SearchConfig(k=1, seed=3, init_pose=tuple(init.tolist()))
    kw = dict(config=cfg, masks=masks, step_mask_index=smask)
    ref = search_reference(P, F, valid, fq, **kw)
    # the take's features are built of frames ahead: the default scan reads the 16-bit frame copy
    # (its residual a few 1e-4 of the features' norm); the 8-bit copy where it is turned off
    framed = SearchIndex(P, F, valid)
    assert framed.frames() is not None and framed.frames().stats[:, 0].max() < 1e-4 * framed.frames().stats[:, 1].max()
    for index in (framed, SearchIndex(P, F, valid, pose_offsets=())):
        fast = index.search(fq, **kw)
        for name, x in fast.array_fields().items():
            assert np.array_equal(x, ref.array_fields()[name], equal_nan=x.dtype.kind == "f"), name
    assert framed._reduced is None  # the frame copy served every step
