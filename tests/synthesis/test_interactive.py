"""The app's computations without streamlit: box selections, uploads, exports, the search record."""

from __future__ import annotations

import dataclasses
import io
import json

import numpy as np
import pytest
import soundfile as sf

from gesturekit import interactive as gs
from gesturekit.control import ControlTrack, constraint_mask, frame_attributes
from gesturekit.demo import build_demo_database
from gesturekit.errors import AudioFileError, ConfigError, GestureKitWarning
from gesturekit.motion import AUDIO_SR
from gesturekit.synthesis import SynthesisConfig, synthesize


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    return build_demo_database(tmp_path_factory.mktemp("db") / "demo", minutes=1.5)


@pytest.fixture(scope="module")
def result(db):
    speech = gs.example_speech("demo speaker, 8 s (generated)")[: 5 * AUDIO_SR]
    config = SynthesisConfig(record=6, control="1-2.5:left_hand=high,2.5-3:speed=slow")
    return synthesize(speech, db=db, config=config)


# ---- box selections ----------------------------------------------------------------------------


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


def test_steps_overview_adds_each_chosen_windows_source(result, db):
    table = result.steps_overview(db)
    assert list(table.columns[:7]) == ["step", "first_frame", "start_s", "clip", "start", "take", "source_s"]
    for row in table.itertuples():
        assert row.take == db.take_names[int(db.clip_take[row.clip])]
        assert row.source_s == pytest.approx((int(db.clip_start[row.clip]) + row.start) / db.fps)


def test_candidates_table_lists_the_recorded_candidates_with_their_source(result, db):
    s = result.search
    for step in (0, s.n_steps // 2, s.n_steps - 1):
        table = result.search.candidates_table(step, db)
        assert len(table) == int(np.count_nonzero(s.cand_clip[step] >= 0)) == 6
        assert list(table["clip"]) == list(s.cand_clip[step])
        assert list(table["chosen"]).index(True) == s.position[step]
        r = table.iloc[1]
        assert r["take"] == db.take_names[int(db.clip_take[r["clip"]])]
        assert r["source_s"] == pytest.approx((int(db.clip_start[r["clip"]]) + r["start"]) / db.fps)
        assert (table["combined"] == table["pose_rank"] + table["audio_rank"]).all()
    with pytest.raises(ConfigError, match="step must be in"):
        result.search.candidates_table(s.n_steps, db)


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


def test_comparison_tables_control_met_is_the_fraction_of_constrained_frames_meeting_them(result, db):
    """The unified control adherence (evaluate.metrics, per segment) against a plain frame-by-frame count."""
    table = gs.comparison_table([result], db.thresholds)
    m = result.motion
    labels = result.control.frame_labels(m.n_frames, fps=m.fps)
    attrs = frame_attributes(m.positions, fps=m.fps)
    met = [bool(constraint_mask(attrs[t], c, dict(db.thresholds))) for t, c in enumerate(labels) if c]
    assert len(met) > 0
    assert table["control_met"][0] == pytest.approx(np.mean(met), abs=1e-12)
    plain = dataclasses.replace(result, config=result.config.with_control(ControlTrack(())))
    assert np.isnan(gs.comparison_table([plain], db.thresholds)["control_met"][0])


def test_without_a_refiner_nothing_changes(result):
    motions, labels = gs.display_motions(result)
    assert motions == [result.motion] and labels == ["k-NN"]


def test_a_silent_upload_warns_naming_the_upload():
    buf = io.BytesIO()
    sf.write(buf, np.zeros(2 * AUDIO_SR, np.float32), AUDIO_SR, format="WAV")
    with pytest.warns(GestureKitWarning, match=r"^quiet\.wav: the audio is silent"):
        audio, _ = gs.read_speech_upload("quiet.wav", buf.getvalue())
    assert not audio.any()
