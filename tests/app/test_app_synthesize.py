"""The Synthesize page, run headless with Streamlit's AppTest: upload, controls, settings, run, result, exports."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from scipy.signal import resample_poly
from streamlit.testing.v1 import AppTest

from gesturekit import interactive as gs
from gesturekit.app import HOME
from gesturekit.control import CONSTRAINTS, frame_attributes
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.export.video import probe_media
from gesturekit.skeleton import N_JOINTS
from gesturekit.viz.figures import WRIST_ROWS
from tests.conftest import chart_spec as chart
from tests.conftest import plotly_array as array
from tests.conftest import shown, viewer
from tests.waits import APP_RUN_S

pytestmark = pytest.mark.slow  # each module builds its demo database (demo_home) and runs pages in AppTest

PAGE = "views/1_Synthesize.py"
TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)
EDITOR = "synth.segments_editor"


@pytest.fixture(scope="module")
def db(demo_home) -> MatchingDatabase:
    return MatchingDatabase.load(demo_home / "db" / "demo")


def speech_file(seconds: float = 4.0, *, sr: int = 16000, channels: int = 1, fmt: str = "WAV") -> bytes:
    """Generated speech of the demo speaker (not in the database) as an audio file's bytes."""
    take, _ = generate_demo_take(seconds=seconds, seed=777, name="speech")
    audio = take.audio if sr == 16000 else resample_poly(take.audio, sr // 50, 320).astype(np.float32)
    data = np.stack([audio] * channels, axis=1) if channels > 1 else audio
    buf = io.BytesIO()
    sf.write(buf, data, sr, format=fmt)
    return buf.getvalue()


def open_page() -> AppTest:
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.switch_page(PAGE).run()
    assert not at.exception, at.exception
    return at


def upload(at: AppTest, data: bytes, name: str = "speech.wav") -> AppTest:
    at.file_uploader(key="synth.upload").set_value((name, data, "audio/wav")).run()
    assert not at.exception, at.exception
    return at


def add_rows(at: AppTest, *rows: dict) -> AppTest:
    """Type rows into the control table, as the data editor would report them."""
    at.session_state[EDITOR] = {"edited_rows": {}, "added_rows": list(rows), "deleted_rows": []}
    return at.run()


def timeline_edit(at: AppTest, edit: str, ranges: list[tuple], curve: dict | None = None) -> AppTest:
    """An edit in the control timeline, as its page in the browser reports it: (lane, level, start, end) ranges."""
    at.session_state["synth.timeline"] = {
        "edit": edit,
        "ranges": [{"lane": a, "level": b, "start_s": s, "end_s": e} for a, b, s, e in ranges],
        "curve": curve,
    }
    return at.run()


def timeline_args(at: AppTest) -> dict:
    """The args the control timeline (app/timeline.py) was drawn with."""
    import json

    for el in at.get("component_instance"):
        if el.proto.component_name.endswith("control_timeline"):
            return json.loads(el.proto.json_args)
    raise AssertionError("no control timeline on the page")


def shown_ranges(at: AppTest) -> list[tuple[str, str, float, float]]:
    return sorted((r["lane"], r["level"], r["start_s"], r["end_s"]) for r in timeline_args(at)["ranges"])


def bands(spec: dict) -> list[tuple[float, float, str]]:
    return sorted(
        {
            (round(s["x0"], 6), round(s["x1"], 6), s["name"])
            for s in spec["layout"].get("shapes", [])
            if s["type"] == "rect"
        }
    )


def errors(at: AppTest) -> list[str]:
    return [shown(e.value) for e in at.error]


def result(at: AppTest):
    return at.session_state["gk.synthesis"]["result"]


def test_upload_a_control_segment_and_run_shows_the_result(app_env, db):
    at = upload(open_page(), speech_file(4.0, sr=22050, channels=2))
    assert any("WAV (PCM_16), 22050 Hz, 2 channels, 4.00 s" in shown(c.value) for c in at.caption)
    at = add_rows(at, {"start_s": 1.0, "end_s": 2.5, "constraint": "left_hand=high"})
    assert not at.exception and not errors(at)
    assert shown_ranges(at) == [("left_hand", "high", 1.0, 2.5)]
    # the demo database offers its shipped refiner; this test looks at the k-NN motion alone
    if at.toggle(key="_w.synth.refine").value:
        at.toggle(key="_w.synth.refine").set_value(False).run()

    at.button(key="synth.go").click().run()
    assert not at.exception and not errors(at)
    res = result(at)
    assert res.refined_motion is None
    assert res.config.control == "1-2.5:left_hand=high" and res.source == "speech.wav"
    assert res.n_frames == 60

    # the 3D view: every joint of the first frame at the result's positions, one animation frame per frame
    # without a refiner: the hard joins beside the blended output
    skel = viewer(at, "synth.skeleton")
    assert len(skel["motions"]) == 2 and len(skel["times"]) == res.n_frames
    hard, m = skel["motions"]

    def shown_at(motion, f):  # the joints of frame f (the second figure stands to the side: its offset removed)
        p = np.asarray(motion["points"][f][:N_JOINTS])
        return p - np.asarray(motion["points"][0][0]) + res.motion.positions[0, 0]

    # posed by the rig's rotations, sent as int16 quaternions: their rounding moves a fingertip by under 2 mm
    np.testing.assert_allclose(shown_at(m, 0), res.motion.positions[0], atol=2e-3)
    np.testing.assert_allclose(shown_at(m, 9), res.motion.positions[9], atol=2e-3)  # after a join
    np.testing.assert_allclose(shown_at(hard, 9), res.knn_motion.positions[9], atol=2e-3)
    assert skel["up"] == [0, 1, 0] and skel["look"]["view"][2] > 0  # in front of the character, Y up

    # the wrist plot: the result's own wrist heights and speeds, the control band, the thresholds
    wrists = chart(at, "synth.wrists")
    motions = (res.knn_motion, res.motion)  # the hard joins and the output, as in the 3D view
    attrs = [frame_attributes(m.positions, fps=res.motion.fps) for m in motions]
    for trace in wrists["data"]:
        col = db.attribute_names.index(trace["meta"]["attribute"])
        np.testing.assert_allclose(array(trace["y"]), attrs[trace["meta"]["motion"]][:, col], atol=1e-5)
    assert sorted(t["meta"]["attribute"] for t in wrists["data"]) == sorted(2 * [a for a, _ in WRIST_ROWS])
    assert set(bands(wrists)) == {(1.0, 2.5, "left_hand=high")}
    lines = {s["name"]: s["y0"] for s in wrists["layout"]["shapes"] if s["type"] == "line"}
    assert lines["left_hand_height high"] == pytest.approx(db.thresholds["left_hand_height"][1])

    # the uploaded speech's player; the result's speech plays in the 3D view, on its clock
    assert len(at.get("audio")) == 1
    np.testing.assert_allclose(skel["audio"][: len(res.audio)], res.audio, atol=1e-4)
    labels = [d.proto.label for d in at.get("download_button")]
    assert labels == [
        "Motion + search (npz)",
        "Motion (BVH)",
        "Character (glTF)",
        "Speech (WAV)",
        "Control track (CSV)",
        "Config (JSON)",
    ]
    assert any(c.value == "MP4: render it above" for c in at.caption)


def test_a_first_visit_opens_on_example_speech_until_a_file_is_uploaded(app_env):
    at = open_page()
    hint = "Until you upload a file, the page works on example speech."
    example = next(iter(gs.SPEECH_EXAMPLES))
    assert at.radio(key="_w.synth.mode").value == "Upload a file"
    assert [shown(c.value) for c in at.caption if shown(c.value) == hint] == [hint]
    assert any(shown(c.value).startswith(f"{example} ·") for c in at.caption)
    assert timeline_args(at)["duration_s"] == pytest.approx(gs.SPEECH_EXAMPLES[example][0], abs=0.05)
    assert not at.button(key="synth.go").disabled

    at = upload(at, speech_file(3.0), name="mine.wav")
    assert not [c for c in at.caption if shown(c.value) == hint]
    assert any(shown(c.value).startswith("mine.wav ·") for c in at.caption)
    assert timeline_args(at)["duration_s"] == pytest.approx(3.0, abs=0.05)
    at.button(key="synth.go").click().run()
    assert not at.exception and result(at).source == "mine.wav" and result(at).n_frames == 45

    # removing the file keeps the uploaded speech (the uploader also forgets it on a page switch)
    at.file_uploader(key="synth.upload").set_value(None).run()
    assert any(shown(c.value).startswith("mine.wav ·") for c in at.caption)


def test_timeline_edits_become_the_control_table_and_table_edits_the_timeline(app_env, db):
    at = upload(open_page(), speech_file(4.0))
    args = timeline_args(at)
    assert [lane["name"] for lane in args["lanes"]] == list(CONSTRAINTS)
    assert args["step_s"] == pytest.approx(8 / 15) and args["ranges"] == []
    lane = next(x for x in args["lanes"] if x["name"] == "left_hand")
    assert lane["levels"] == ["low", "high"] and lane["curve"]
    assert (lane["low"], lane["high"]) == pytest.approx(db.thresholds["left_hand_height"])

    # two lanes overlapping: the table holds one row per range, the track cuts where each begins and ends
    at = timeline_edit(at, "s-1", [("speed", "fast", 0.533333, 2.133333), ("left_hand", "low", 1.066667, 3.2)])
    assert not at.exception and not errors(at)
    rows = at.data_editor[0].value.to_dict("records")
    assert rows == [
        {"start_s": 0.533333, "end_s": 2.133333, "constraint": "speed=fast"},
        {"start_s": 1.066667, "end_s": 3.2, "constraint": "left_hand=low"},
    ]
    assert shown_ranges(at) == [("left_hand", "low", 1.066667, 3.2), ("speed", "fast", 0.533333, 2.133333)]
    assert timeline_args(at)["edit"] == "s-1"  # the timeline knows the page holds its edit
    at.run()  # the same edit again changes nothing
    assert len(at.data_editor[0].value) == 2

    # a row typed into the table shows in the timeline
    at = add_rows(at, {"start_s": 3.2, "end_s": 4.0, "constraint": "width=wide"})
    assert ("width", "wide", 3.2, 4.0) in shown_ranges(at)

    # one lane overlapping itself is refused in words, naming the rows
    at = add_rows(at, {"start_s": 1.0, "end_s": 2.0, "constraint": "speed=slow"})
    assert any("both set speed" in e for e in errors(at)), errors(at)
    assert at.button(key="synth.go").disabled

    at.button(key="synth.clear_segments").click().run()
    assert at.data_editor[0].value.empty and shown_ranges(at) == []


def test_a_curve_drawn_in_the_timeline_becomes_ranges_step_by_step(app_env, db):
    at = upload(open_page(), speech_file(4.0))
    low, high = db.thresholds["right_hand_height"]
    # above the high threshold over the first second, below the low one from 2 s on
    curve = {
        "lane": "right_hand",
        "t": [0.0, 1.0, 1.01, 2.0, 2.01, 4.0],
        "y": [high + 0.1] * 2 + [0.5 * (low + high)] * 2 + [low - 0.1] * 2,
    }
    at = timeline_edit(at, "c-1", [("speed", "slow", 0.0, 4.0)], curve=curve)
    assert not at.exception and not errors(at)
    got = shown_ranges(at)
    step = 8 / 15
    assert got == [
        ("right_hand", "high", 0.0, round(2 * step, 6)),
        ("right_hand", "low", round(4 * step, 6), 4.0),
        ("speed", "slow", 0.0, 4.0),
    ]


def test_a_bad_upload_is_an_error_message_not_a_traceback(app_env):
    at = upload(open_page(), b"these are my notes, not sound" * 20, name="notes.wav")
    (err,) = errors(at)
    assert err.startswith("notes.wav: ")
    assert not at.exception and not at.get("plotly_chart")
    assert "synth.go" not in [b.key for b in at.button]
    at.run()  # the same upload is not read again, and still reported
    assert errors(at) == [err]
    # an example instead: back to work
    at.radio(key="_w.synth.mode").set_value("Example speech").run()
    assert not errors(at) and at.button(key="synth.go")


def test_a_failed_upload_keeps_the_last_result_and_speech_in_view(app_env):
    at = upload(open_page(), speech_file(3.0), name="good.wav")
    if at.toggle(key="_w.synth.refine").value:
        at.toggle(key="_w.synth.refine").set_value(False).run()
    at.button(key="synth.go").click().run()
    assert not errors(at) and viewer(at, "synth.skeleton")
    at = upload(at, b"these are my notes, not sound" * 20, name="notes.wav")
    (err,) = errors(at)
    assert err.startswith("notes.wav: ")
    assert not at.exception
    assert at.session_state["synth.speech"]["name"] == "good.wav"  # the last readable file is still the speech
    assert any("Still working on good.wav," in shown(c.value) for c in at.caption)
    assert viewer(at, "synth.skeleton") and result(at).source == "good.wav"  # the result stays
    assert not at.button(key="synth.go").disabled
    at.run()  # the failed file is not read again, and still reported above the result
    assert errors(at) == [err] and viewer(at, "synth.skeleton")


def test_settings_that_differ_from_the_paper_are_named(app_env):
    at = open_page()
    at.radio(key="_w.synth.mode").set_value("Example speech").run()
    if at.toggle(key="_w.synth.refine").value:
        at.toggle(key="_w.synth.refine").set_value(False).run()
    # without a refiner the joins are blended by default: our one departure, named
    (note,) = [shown(c.value) for c in at.caption if shown(c.value).startswith("Differs from the paper")]
    assert note == "Differs from the paper: blending: dead (paper none)"
    at.selectbox(key="_w.synth.blend").set_value("none").run()
    assert not [c.value for c in at.caption if "Differs from the paper" in c.value]  # the paper's settings
    at.number_input(key="_w.synth.segment").set_value(6)
    at.selectbox(key="_w.synth.init").set_value("rest").run()
    (note,) = [shown(c.value) for c in at.caption if shown(c.value).startswith("Differs from the paper")]
    assert note == "Differs from the paper: N = 6 (paper 8); initial pose: rest (paper random)"
    at.button(key="synth.go").click().run()
    assert not at.exception and not errors(at)
    assert result(at).config.segment == 6
    assert any(
        "differs from the paper: N = 6 (paper 8); initial pose: rest (paper random)" in shown(c.value)
        for c in at.caption
        if "seed" in shown(c.value)
    )


def test_a_silent_upload_is_accepted_with_a_warning(app_env):
    buf = io.BytesIO()
    sf.write(buf, np.zeros(32000, np.float32), 16000, format="WAV")
    at = upload(open_page(), buf.getvalue(), name="quiet.wav")
    assert [shown(w.value) for w in at.main.warning if "silent" in shown(w.value)] == [
        "quiet.wav: the audio is silent (peak level at or below -80 dBFS)"
    ]
    assert not errors(at) and not at.button(key="synth.go").disabled


def test_an_invalid_control_row_blocks_the_run(app_env):
    at = add_rows(upload(open_page(), speech_file(3.0)), {"start_s": 2.0, "end_s": 1.0, "constraint": "speed=slow"})
    (err,) = errors(at)
    assert err.startswith("control row 1:") and "end must be after start" in err
    assert at.button(key="synth.go").disabled
    assert not at.exception


def test_settings_reach_the_config_and_survive_a_page_switch(app_env):
    at = open_page()
    at.radio(key="_w.synth.mode").set_value("Example speech").run()
    at.number_input(key="_w.synth.k").set_value(2)
    at.number_input(key="_w.synth.seed").set_value(3)
    at.number_input(key="_w.synth.record").set_value(4)
    at.selectbox(key="_w.synth.init").set_value("rest")
    at.selectbox(key="_w.synth.blend").set_value("offset")
    at.selectbox(key="_w.synth.mask_rule").set_value("all").run()
    at = add_rows(at, {"start_s": 0.0, "end_s": 2.0, "constraint": "both_hands=low"})
    at.button(key="synth.go").click().run()
    assert not at.exception and not errors(at)
    c = result(at).config
    assert (c.k, c.seed, c.record, c.init, c.blend, c.mask_rule) == (2, 3, 4, "rest", "offset", "all")
    assert c.control == "0-2:both_hands=low"
    assert result(at).n_frames == 8 * 15  # the 8 s example

    at.switch_page("views/3_Database.py").run()
    at.switch_page(PAGE).run()
    assert not at.exception
    assert at.number_input(key="_w.synth.k").value == 2 and at.selectbox(key="_w.synth.blend").value == "offset"
    assert at.data_editor[0].value.to_dict("records") == [
        {"start_s": 0.0, "end_s": 2.0, "constraint": "both_hands=low"}
    ]
    assert viewer(at, "synth.skeleton")  # the result is still there

    other = open_page()  # another user sees none of it: a first visit, on the example speech
    assert "gk.synthesis" not in other.session_state
    assert not [c for c in other.get("component_instance") if c.proto.component_name.endswith("skeleton_viewer")]
    assert other.number_input(key="_w.synth.k").value == 0 and other.data_editor[0].value.empty
    assert other.session_state["synth.speech"]["token"] == ("example", "demo speaker, 8 s (generated)")


def test_rendering_the_video_gives_an_mp4_with_the_speech(app_env, tmp_path):
    at = upload(open_page(), speech_file(2.0))
    at.button(key="synth.go").click().run()
    at.button(key="synth.render").click().run()
    assert not at.exception and not errors(at)
    assert len(at.get("video")) == 1
    assert [d.proto.label for d in at.get("download_button")][-1] == "Video (MP4)"
    mp4 = tmp_path / "result.mp4"
    mp4.write_bytes(at.session_state["_synth.video"]["bytes"])
    info = probe_media(mp4)
    assert info["video"]["codec"] == "h264" and info["audio"]["codec"] == "aac"
    assert info["video"]["frames"] == result(at).n_frames == 30
    assert info["audio"]["duration"] == pytest.approx(2.0, abs=0.03)
    assert at.session_state["_synth.video"]["framing"] == "upper body"
    # the full body: the video made before no longer stands for the choice; rendered again, framed so
    at.checkbox(key="synth.video_full_body").check().run()
    assert not at.get("video") and at.button(key="synth.render")
    at.button(key="synth.render").click().run()
    assert not at.exception and len(at.get("video")) == 1
    assert at.session_state["_synth.video"]["framing"] == "full body"


def test_with_a_refiner_k_nn_and_refined_are_shown_side_by_side(app_env, tmp_path, monkeypatch):
    """The page's side of the refiner: a stand-in refiner that smooths the k-NN motion over 5 frames."""
    import dataclasses

    from scipy.ndimage import uniform_filter1d

    import gesturekit.synthesis as synthesis
    from gesturekit.motion import Motion

    real = synthesis.synthesize
    seen = []

    def synthesize(audio, *, db, config=None, control=None, refiner=None):
        res = real(audio, db=db, config=config, control=control)
        if refiner is None:
            return res
        seen.append(refiner)
        smooth = Motion(uniform_filter1d(res.knn_motion.positions, 5, axis=0), res.motion.fps)
        return dataclasses.replace(res, motion=smooth, refined_motion=smooth)

    class StandIn:
        def check_database(self, db):
            pass

        def refine(self, motion, audio):  # the page's background warm-up runs one pass
            return motion

    folder = tmp_path / "my-refiner"
    folder.mkdir()
    (folder / "config.json").write_text("{}", encoding="utf-8")
    monkeypatch.setattr("gesturekit.synthesis.synthesize", synthesize)
    monkeypatch.setattr("gesturekit.refine.load_refiner", lambda path: StandIn())
    checked = []
    monkeypatch.setattr("gesturekit.refine.check_refiner", lambda path, db: checked.append(path) or Path(path))

    at = upload(open_page(), speech_file(3.0))
    at.toggle(key="_w.synth.refine").set_value(True).run()
    at.text_input(key="_w.synth.refiner_path").input(str(folder)).run()
    at.button(key="synth.go").click().run()
    assert not at.exception and not errors(at)
    assert len(seen) == 1 and isinstance(seen[0], StandIn)
    assert checked and Path(checked[-1]) == folder  # checked when chosen, loaded when run
    skel = viewer(at, "synth.skeleton")
    assert [m["label"] for m in skel["motions"]] == ["k-NN", "k-NN + refiner"]
    wrists = chart(at, "synth.wrists")
    res = result(at)
    speeds = {t["meta"]["motion"]: array(t["y"]) for t in wrists["data"] if t["meta"]["attribute"] == "left_hand_speed"}
    np.testing.assert_allclose(speeds[0], frame_attributes(res.knn_motion.positions)[:, 2], atol=1e-5)
    np.testing.assert_allclose(speeds[1], frame_attributes(res.refined_motion.positions)[:, 2], atol=1e-5)
    assert any("refined" in shown(c.value) for c in at.caption)

    # the refiner on but not loadable: an error, and no run without it
    at.text_input(key="_w.synth.refiner_path").input("").run()
    assert any("folder of a trained refiner" in e for e in errors(at))
    assert at.button(key="synth.go").disabled


def _page_text(at: AppTest) -> list[str]:
    """Every text an audience reads on the page: markdown, captions, notes, labels of buttons and downloads."""
    texts = []
    for kind in ("markdown", "caption", "info", "success", "warning", "error", "title", "header", "subheader"):
        texts += [shown(str(e.value)) for e in at.get(kind)]
    texts += [str(d.proto.label) for d in at.get("download_button")]
    texts += [str(b.label) for b in at.button]
    return texts


def test_a_run_shows_no_server_paths_flags_or_source_strings(app_env, db):
    from gesturekit.refine import default_refiner_path

    at = open_page()
    at.radio(key="_w.synth.mode").set_value("Example speech").run()
    at.button(key="synth.go").click().run()
    assert not at.exception and not errors(at)
    assert result(at).refined_motion is not None  # the demo refiner, on by default: its path is not shown
    texts = _page_text(at)
    assert texts
    home = str(app_env)  # the server's folders: the databases, the refiner, the working folder
    for text in texts:
        for path in (home, str(db.path), str(default_refiner_path()), str(Path.cwd())):
            assert path not in text, text
        assert " --" not in text and not text.startswith("--"), text  # no command-line flags
        assert "gesturekit.datasets" not in text and "generator=" not in text, text
    assert not [w for w in at.main.warning if "off the motion" in shown(w.value)]  # the demo's files are exact
