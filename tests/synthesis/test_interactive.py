"""The app's computations without streamlit: control tables, box selections, uploads, exports, the search record."""

from __future__ import annotations

import io
import json

import numpy as np
import pandas as pd
import pytest
import soundfile as sf
from hypothesis import given, settings
from hypothesis import strategies as hst

from gesturekit import interactive as gs
from gesturekit.control import ControlTrack, Segment, parse_control
from gesturekit.demo import build_demo_database
from gesturekit.errors import AudioFileError, ConfigError, GestureKitWarning
from gesturekit.motion import AUDIO_SR, Motion
from gesturekit.skeleton import N_JOINTS, joint_index
from gesturekit.synthesize import SynthesisConfig, synthesize


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    return build_demo_database(tmp_path_factory.mktemp("db") / "demo", minutes=1.5)


@pytest.fixture(scope="module")
def result(db):
    speech = gs.example_speech("demo speaker, 8 s (generated)")[: 5 * AUDIO_SR]
    config = SynthesisConfig(record=6, control="1-2.5:left_hand=high,2.5-3:speed=slow")
    return synthesize(speech, db=db, config=config)


# ---- the control table --------------------------------------------------------------------------


def test_rows_with_the_same_times_form_one_segment_and_blank_rows_are_ignored():
    table = pd.DataFrame(
        [
            {"start_s": 3.0, "end_s": 4.0, "constraint": "speed=slow"},
            {"start_s": None, "end_s": None, "constraint": None},  # a row just added in the editor
            {"start_s": 0.5, "end_s": 2.0, "constraint": "left_hand=high"},
            {"start_s": 0.5, "end_s": 2.0, "constraint": "width=wide"},
        ]
    )
    track = gs.track_from_segments(table)
    assert track.to_text() == "0.5-2:left_hand=high+width=wide,3-4:speed=slow"


@pytest.mark.parametrize(
    "rows, message",
    [
        ([{"start_s": 1.0, "end_s": None, "constraint": "speed=slow"}], "control row 1: fill in end_s"),
        (
            [
                {"start_s": 1.0, "end_s": 2.0, "constraint": "speed=slow"},
                {"start_s": 3.0, "end_s": 2.0, "constraint": "speed=fast"},
            ],
            "control row 2: .*end must be after start",
        ),
        ([{"start_s": 1.0, "end_s": 2.0, "constraint": "hands=up"}], "control row 1: unknown constraint 'hands=up'"),
        (
            [
                {"start_s": 1.0, "end_s": 2.0, "constraint": "speed=slow"},
                {"start_s": 1.0, "end_s": 2.0, "constraint": "speed=fast"},
            ],
            "control row 2: speed is set twice .*row 1",
        ),
        (
            [
                {"start_s": 1.0, "end_s": 3.0, "constraint": "speed=slow"},
                {"start_s": 2.0, "end_s": 4.0, "constraint": "width=wide"},
            ],
            "overlap",
        ),
        (
            [{"start_s": "soon", "end_s": 2.0, "constraint": "speed=slow"}],
            "control row 1: start_s and end_s must be numbers",
        ),
    ],
)
def test_invalid_rows_are_config_errors_naming_the_row(rows, message):
    with pytest.raises(ConfigError, match=message):
        gs.track_from_segments(rows)


_constraint = hst.sampled_from(gs.CONSTRAINT_CHOICES)


@hst.composite
def _tracks(draw):
    """Non-overlapping segments on a 0.05 s grid, each with 1-2 constraints of distinct controls."""
    cuts = sorted(draw(hst.sets(hst.integers(0, 400), min_size=0, max_size=10)))
    segs = []
    for a, b in zip(cuts[::2], cuts[1::2]):
        picked = draw(hst.lists(_constraint, min_size=1, max_size=2, unique_by=lambda c: c.split("=")[0]))
        segs.append(Segment(a * 0.05, b * 0.05, tuple(tuple(c.split("=")) for c in picked)))
    return ControlTrack(tuple(segs))


@settings(max_examples=60, deadline=None)
@given(track=_tracks())
def test_a_track_survives_the_table(track):
    assert gs.track_from_segments(gs.segments_frame(track)) == track


def test_adding_a_segment_cuts_what_it_overlaps():
    table = gs.segments_frame(parse_control("0-4:speed=slow,5-6:width=wide"))
    out = gs.add_segment(table, 1.0, 2.0, "left_hand=high")
    assert gs.track_from_segments(out).to_text() == "0-1:speed=slow,1-2:left_hand=high,2-4:speed=slow,5-6:width=wide"
    out = gs.add_segment(out, 3.5, 5.5, "speed=fast")
    assert (
        gs.track_from_segments(out).to_text()
        == "0-1:speed=slow,1-2:left_hand=high,2-3.5:speed=slow,3.5-5.5:speed=fast,5.5-6:width=wide"
    )
    with pytest.raises(ConfigError, match="unknown constraint"):
        gs.add_segment(out, 0, 1, "nonsense")


@settings(max_examples=60, deadline=None)
@given(adds=hst.lists(hst.tuples(hst.integers(0, 100), hst.integers(1, 30), _constraint), min_size=1, max_size=8))
def test_any_sequence_of_additions_leaves_a_valid_table_ending_with_the_last_range(adds):
    table = gs.empty_segments()
    for a, length, constraint in adds:
        table = gs.add_segment(table, a / 10, (a + length) / 10, constraint)
    track = gs.track_from_segments(table)  # never overlapping
    a, length, constraint = adds[-1]
    name, value = constraint.split("=")
    covering = [s for s in track.segments if s.start_s <= a / 10 + 1e-9 and s.end_s >= (a + length) / 10 - 1e-9]
    assert len(covering) == 1 and covering[0].constraints == ((name, value),)


@pytest.mark.parametrize(
    "selection, expected",
    [
        ({"box": [{"x": [2.3456, 0.5], "y": [0, 1]}]}, (0.5, 2.35)),
        ({"box": [{"x": [1, 2]}, {"x": [-1.0, 9.0]}]}, (0.0, 6.0)),  # the latest box, clipped to the speech
        ({"box": [{"x": [1.0, 1.02]}]}, None),  # a click, not a range
        ({"box": [], "points": [{"x": 1}]}, None),
        (None, None),
    ],
)
def test_box_selection_gives_a_time_range(selection, expected):
    assert gs.selected_time_range(selection, duration=6.0) == expected


# ---- speech -------------------------------------------------------------------------------------


def test_an_upload_in_any_layout_becomes_mono_16k_and_keeps_its_name():
    t = np.arange(2 * 44100) / 44100
    stereo = np.stack([np.sin(2 * np.pi * 220 * t), 0.5 * np.sin(2 * np.pi * 330 * t)], axis=1) * 0.3
    buf = io.BytesIO()
    sf.write(buf, stereo, 44100, format="FLAC")
    audio, info = gs.read_speech_upload("my talk.flac", buf.getvalue())
    assert audio.dtype == np.float32 and audio.ndim == 1 and abs(len(audio) - 2 * AUDIO_SR) <= 1
    assert (info.format, info.sample_rate, info.channels, info.path) == ("FLAC", 44100, 2, "my talk.flac")


def test_an_unreadable_upload_names_the_uploaded_file():
    with pytest.raises(AudioFileError) as err:
        gs.read_speech_upload("notes.wav", b"not audio at all" * 50)
    assert str(err.value).startswith("notes.wav: ") and "gesturekit-upload" not in str(err.value)


def test_example_speech_is_generated_and_deterministic():
    a = gs.example_speech("demo speaker, 8 s (generated)")
    assert a.shape == (8 * AUDIO_SR,) and a.dtype == np.float32 and np.abs(a).max() > 0.05
    np.testing.assert_array_equal(a, gs.example_speech("demo speaker, 8 s (generated)"))
    with pytest.raises(ConfigError, match="no example speech"):
        gs.example_speech("a file from somewhere")


# ---- exports ------------------------------------------------------------------------------------


def test_exports_hold_the_result_and_how_it_was_made(result, tmp_path):
    data = gs.export_bytes(result, "npz")
    (tmp_path / "r.npz").write_bytes(data)
    with np.load(tmp_path / "r.npz", allow_pickle=False) as z:
        np.testing.assert_array_equal(z["positions"], result.motion.positions)
        np.testing.assert_array_equal(z["search_clip"], result.search.clip)
    assert gs.export_bytes(result, "bvh").startswith(b"HIERARCHY")
    assert (
        gs.export_bytes(result, "csv").decode()
        == "start_s,end_s,constraint\n1.0,2.5,left_hand=high\n2.5,3.0,speed=slow\n"
    )
    meta = json.loads(gs.export_bytes(result, "json"))
    assert SynthesisConfig.from_dict(meta["synthesis"]) == result.config
    assert meta["frames"] == result.n_frames
    import soundfile as sf

    speech, sr = sf.read(io.BytesIO(gs.export_bytes(result, "wav")), dtype="float32")
    assert sr == AUDIO_SR and speech.shape == result.audio.shape
    np.testing.assert_allclose(speech, np.clip(result.audio, -1, 1), atol=1 / 2**15)
    assert gs.export_filename(result, "wav").endswith(".wav")
    with pytest.raises(ConfigError):
        gs.export_bytes(result, "exe")


def test_download_names_are_safe(result):
    from dataclasses import replace

    odd = replace(result, source="../../Café talk?.wav")
    assert gs.export_filename(odd, "bvh") == "Cafe_talk_k0_seed0.bvh"
    assert gs.export_filename(odd, "csv").endswith("_control.csv")


# ---- the search record --------------------------------------------------------------------------


def test_candidates_table_lists_the_recorded_candidates_with_their_source(result, db):
    s = result.search
    for step in (0, s.n_steps // 2, s.n_steps - 1):
        table = gs.candidates_table(result, db, step)
        assert len(table) == int(np.count_nonzero(s.cand_clip[step] >= 0)) == 6
        assert list(table["clip"]) == list(s.cand_clip[step])
        assert list(table["chosen"]).index(True) == s.position[step]
        r = table.iloc[1]
        assert r["take"] == db.take_names[int(db.clip_take[r["clip"]])]
        assert r["source_s"] == pytest.approx((int(db.clip_start[r["clip"]]) + r["start"]) / db.fps)
        assert (table["combined"] == table["pose_rank"] + table["audio_rank"]).all()
    with pytest.raises(ConfigError, match="step must be in"):
        gs.candidates_table(result, db, s.n_steps)


def test_step_audio_and_candidate_motion_cover_one_step(result, db):
    N = result.config.segment
    assert len(gs.step_speech(result, 2)) == N * AUDIO_SR // 15
    m = gs.candidate_motion(db, int(result.search.clip[2]), int(result.search.start[2]), N)
    np.testing.assert_array_equal(m.positions, result.knn_motion.positions[2 * N : 3 * N])


def test_comparing_k_matches_single_runs(result, db):
    results = gs.compare_k(result.audio, db=db, config=result.config, ks=[0, 2], source="talk.wav")
    assert [r.config.k for r in results] == [0, 2] and {r.source for r in results} == {"talk.wav"}
    assert results[0].search.equals(result.search)
    single = synthesize(result.audio, db=db, config=SynthesisConfig.from_dict({**result.config.to_dict(), "k": 2}))
    assert results[1].search.equals(single.search)
    table = gs.comparison_table(results, db.thresholds)
    assert list(table["k"]) == [0, 2]
    s = result.search
    assert table["pose_dist"][0] == pytest.approx(np.mean(s.cand_pose_dist[np.arange(s.n_steps), s.position]))
    assert 0.0 <= table["control_met"][0] <= 1.0


def test_control_adherence_counts_constrained_frames_meeting_their_constraint():
    pos = np.zeros((30, N_JOINTS, 3), dtype=np.float32)
    pos[:15, joint_index("left_wrist"), 1] = 0.5  # high for the first second, low after
    motion = Motion(pos, 15.0)
    thresholds = {"left_hand_height": (0.1, 0.4)}
    assert gs.control_adherence(motion, parse_control("0-1:left_hand=high"), thresholds) == 1.0
    assert gs.control_adherence(motion, parse_control("0-2:left_hand=high"), thresholds) == 0.5
    assert np.isnan(gs.control_adherence(motion, ControlTrack(()), thresholds))


def test_without_a_refiner_nothing_changes(result):
    motions, labels = gs.display_motions(result)
    assert motions == [result.motion] and labels == ["k-NN"]


def test_a_silent_upload_warns_naming_the_upload():
    buf = io.BytesIO()
    sf.write(buf, np.zeros(2 * AUDIO_SR, np.float32), AUDIO_SR, format="WAV")
    with pytest.warns(GestureKitWarning, match=r"^quiet\.wav: the audio is silent"):
        audio, _ = gs.read_speech_upload("quiet.wav", buf.getvalue())
    assert not audio.any()


def test_players_get_the_audio_at_its_own_level():
    quiet = (0.01 * np.sin(np.linspace(0, 200, AUDIO_SR))).astype(np.float32)
    quiet[10] = 3.0  # beyond full scale: clipped, not rescaled
    back, sr = sf.read(io.BytesIO(gs.wav_bytes(quiet)), dtype="float32")
    assert sr == AUDIO_SR and back.shape == quiet.shape
    assert back[10] == pytest.approx(1.0, abs=1e-4)
    np.testing.assert_allclose(np.delete(back, 10), np.delete(quiet, 10), atol=1 / 32767)
    silent, _ = sf.read(io.BytesIO(gs.wav_bytes(np.zeros(100, np.float32))))
    assert not silent.any()
