"""The Live page and its engine, without a browser: microphone frames in (as PyAV frames at 48 kHz
stereo, as the browser's stream arrives), controls switched while talking, Stop keeps the performance.

The WebRTC transport cannot run under AppTest (it needs a served session); the page's call of
``streamlit_webrtc.webrtc_streamer`` is replaced by a stand-in reporting the stream on or off,
and the test feeds the audio callback the page gave it, as the transport would.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import av
import numpy as np
import pytest
import soxr
import streamlit_webrtc
from hypothesis import given, settings
from hypothesis import strategies as hst
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.synthetic import generate_demo_take
from gesturekit.errors import ConfigError, GestureKitError
from gesturekit.motion import AUDIO_SR
from tests.conftest import shown, viewer
from tests.waits import APP_RUN_S

pytestmark = pytest.mark.slow  # each module builds its demo database (demo_home) and runs pages in AppTest

PAGE = "views/5_Live.py"
RATE = 48000
FRAME = 960  # 20 ms at 48 kHz, as the browser's Opus stream is decoded


@pytest.fixture(scope="module")
def live():
    """The page's engine (``gesturekit/app/live_session.py``), imported as the app imports it."""
    from gesturekit.app import live_session

    return live_session


@pytest.fixture(scope="module")
def db(demo_home) -> MatchingDatabase:
    return MatchingDatabase.load(demo_home / "db" / "demo")


@pytest.fixture(scope="module")
def speech48() -> np.ndarray:
    """6 s of the demo speaker (not in the database) at 48 kHz, as the browser sends it."""
    take, _ = generate_demo_take(seconds=6.0, seed=818, name="speech")
    return soxr.resample(take.audio, AUDIO_SR, RATE, quality="HQ").astype(np.float32)


def stereo_frames(x: np.ndarray, t0: int = 0):
    """PyAV frames of 20 ms, 16-bit interleaved stereo (both channels ``x``), from sample ``t0``."""
    for i in range(0, len(x), FRAME):
        chunk = np.clip(x[i : i + FRAME] * 32767, -32768, 32767).astype(np.int16)
        frame = av.AudioFrame.from_ndarray(np.repeat(chunk, 2)[None, :], format="s16", layout="stereo")
        frame.sample_rate = RATE
        frame.pts = t0 + i
        yield frame


# --- the engine ----------------------------------------------------------------------------------
@settings(max_examples=25, deadline=None)
@given(n=hst.integers(1, 50), channels=hst.integers(1, 3), planar=hst.booleans(), fmt=hst.sampled_from(["s16", "flt"]))
def test_any_frame_layout_becomes_the_mean_of_its_channels(live, n, channels, planar, fmt):
    rng = np.random.default_rng(n * 7 + channels)
    x = rng.uniform(-1, 1, (channels, n)).astype(np.float32)
    raw = (x * 32768).astype(np.int16) if fmt == "s16" else x
    data = raw if planar else raw.T.reshape(1, -1)
    got = live.mono_samples(data, fmt=fmt + ("p" if planar else ""), planar=planar, channels=channels)
    want = (raw.astype(np.float32) / (32768.0 if fmt == "s16" else 1.0)).mean(axis=0)
    assert got.dtype == np.float32 and got.shape == (n,)
    np.testing.assert_allclose(got, want, atol=1e-6)


def test_an_unknown_sample_format_is_refused_with_its_name(live):
    with pytest.raises(ConfigError, match="'u8'"):
        live.mono_samples(np.zeros((1, 4), np.uint8), fmt="u8", planar=False, channels=1)


def test_a_frame_in_a_format_it_cannot_read_is_the_sessions_error_not_the_transports(live, db):
    session = live.LiveSession(db)
    frame = av.AudioFrame.from_ndarray(np.zeros((1, 960), np.uint8), format="u8", layout="mono")
    frame.sample_rate = RATE
    assert session.on_frame(frame) is frame  # the transport is not interrupted
    assert "'u8'" in session.error
    with pytest.raises(GestureKitError, match="u8"):
        session.stop(APP_RUN_S)


def test_frames_in_20_ms_pieces_give_the_speech_resampled_whole(live, db, speech48):
    session = live.LiveSession(db, clock=lambda: 100.0)
    for frame in stereo_frames(speech48):
        assert session.on_frame(frame) is frame  # the stream goes on untouched
    result = session.stop(APP_RUN_S)
    whole = soxr.resample(speech48, RATE, AUDIO_SR, quality="HQ")
    assert abs(len(result.audio) - len(whole)) <= 1
    n = min(len(result.audio), len(whole))
    # 16-bit quantisation of the stream only (a streaming filter equals the whole-file one)
    assert np.max(np.abs(result.audio[:n] - whole[:n])) < 2e-4
    assert result.n_frames == len(result.audio) * 15 // AUDIO_SR
    assert result.motion.positions.shape == (result.n_frames, 55, 3)


def test_the_view_shows_the_newest_frame_and_how_long_ago_its_speech_was_heard(live, db, speech48):
    now = {"t": 1000.0}
    session = live.LiveSession(db, clock=lambda: now["t"])
    n_in = 0
    for i, frame in enumerate(stereo_frames(speech48[: 4 * RATE])):
        now["t"] = 1000.0 + (i + 1) * FRAME / RATE  # each frame arrives once spoken
        session.on_frame(frame)
        n_in += FRAME
        if i in (80, 199):
            assert session.wait(APP_RUN_S)
            view = session.view()
            # the newest frame determined, drawn now
            assert view.frame == view.frames - 1 == session._synth.frames_out - 1
            assert view.t0 == pytest.approx(1000.0)  # the first sample was spoken a frame before it came
            assert view.speech_s == pytest.approx(n_in / RATE)
            # its speech was heard at t0 + its time; the latency is the rest of the way to now
            assert view.latency_s == pytest.approx(now["t"] - (1000.0 + view.frame / db.fps), abs=1e-6)
            # the newest frame waited on nothing but the speech it needs (give or take the packet it came in)
            assert view.latency_s <= view.algorithmic_s + 2 * FRAME / RATE
    later = 0.37
    now["t"] += later  # no speech since: the same frame, its latency grows
    assert session.view().latency_s == pytest.approx(view.latency_s + later)
    session.stop(APP_RUN_S)


def test_a_control_switched_while_talking_holds_from_the_speech_received_on(live, db, speech48):
    session = live.LiveSession(db)
    frames = list(stereo_frames(speech48))
    for f in frames[:150]:  # 3 s
        session.on_frame(f)
    assert session.wait(APP_RUN_S)
    switched_at = session.view().frames / db.fps
    session.set_control("left_hand=high")
    for f in frames[150:]:
        session.on_frame(f)
    assert session.control == "left_hand=high"
    result = session.stop(APP_RUN_S)
    (segment,) = result.control.segments
    assert segment.constraints == (("left_hand", "high"),)
    assert segment.start_s == pytest.approx(switched_at, abs=1 / db.fps)
    assert segment.end_s >= (result.n_frames - 1) / db.fps  # held to the end


def test_a_bad_control_is_shown_as_the_sessions_error_and_stop_raises_it(live, db, speech48):
    session = live.LiveSession(db)
    for f in list(stereo_frames(speech48))[:20]:
        session.on_frame(f)
    session.set_control("left_hand=sideways")
    assert session.wait(APP_RUN_S)
    assert "left_hand" in session.error and "sideways" in session.error
    with pytest.raises(GestureKitError, match="sideways"):
        session.stop(APP_RUN_S)


def test_stop_after_a_stop_starts_nothing_until_the_stream_is_off(live, db, speech48):
    stage = live.LiveStage()
    stage.configure(lambda control: live.LiveSession(db, control=control))
    frames = list(stereo_frames(speech48))
    for f in frames[:60]:
        stage.on_frame(f)
    result, made_with = stage.stop()
    assert made_with is db and result.n_frames == 60 * FRAME * 15 // RATE
    for f in frames[60:70]:  # the microphone takes a moment to close
        stage.on_frame(f)
    assert stage.session is None and stage.stop() is None
    stage.rearm()  # the stream is off: the next frames begin a new performance
    for f in frames[:10]:
        stage.on_frame(f)
    assert stage.session is not None
    assert stage.stop()[0].n_frames == 10 * FRAME * 15 // RATE


def test_a_control_chosen_before_start_holds_from_the_first_frame(live, db, speech48):
    stage = live.LiveStage()
    stage.configure(lambda control: live.LiveSession(db, control=control))
    stage.set_control("left_hand=low")  # no performance yet: it is kept for the next
    for f in stereo_frames(speech48[: 3 * RATE]):
        stage.on_frame(f)
    result, _ = stage.stop()
    (segment,) = result.control.segments
    assert segment.start_s == 0 and segment.label() == "left_hand=low"


def test_no_ice_server_unless_the_environment_names_some(live):
    assert live.rtc_configuration({}) == {"iceServers": []}
    servers = [{"urls": ["turn:turn.example.org:3478"], "username": "u", "credential": "c"}]
    assert live.rtc_configuration({live.ICE_SERVERS_ENV: json.dumps(servers)}) == {"iceServers": servers}


@pytest.mark.parametrize(
    "value, problem",
    [
        ("stun:stun.example.org", "is not JSON"),
        ('{"urls": "stun:x"}', "must be a JSON list"),
        ('[{"url": "stun:x"}]', "each with its urls"),
    ],
)
def test_bad_ice_servers_are_refused_naming_the_variable(live, value, problem):
    with pytest.raises(ConfigError, match=problem) as err:
        live.rtc_configuration({live.ICE_SERVERS_ENV: value})
    assert "$GESTUREKIT_ICE_SERVERS" in str(err.value)


def test_the_page_says_what_is_wrong_with_the_ice_servers(app_env, mic, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_ICE_SERVERS", "not json")
    at = open_live(mic)
    assert any("GESTUREKIT_ICE_SERVERS" in shown(e.value) and "not JSON" in shown(e.value) for e in at.error)
    assert not at.exception


# --- the page --------------------------------------------------------------------------------------
@pytest.fixture
def mic(monkeypatch):
    """Replace the WebRTC component: ``mic.playing`` is the stream's state; ``mic.callback`` the
    audio sink's callback and ``mic.calls`` the arguments of the page's last call."""
    box = SimpleNamespace(playing=False, callback=None, calls=[])

    def fake(key, **kwargs):
        box.callback = kwargs["sink_audio_track"]._callback  # the transport hands it every frame
        box.calls.append(dict(kwargs, key=key))
        return SimpleNamespace(state=SimpleNamespace(playing=box.playing))

    monkeypatch.setattr(streamlit_webrtc, "webrtc_streamer", fake)
    return box


def open_live(mic) -> AppTest:
    at = AppTest.from_file(str(HOME), default_timeout=APP_RUN_S).run()
    at.switch_page(PAGE).run()
    assert not at.exception, at.exception
    return at


def button(at: AppTest, key: str):
    return next(b for b in at.button if b.key == key)


def test_the_microphone_asks_for_audio_only_and_names_no_outside_server(app_env, mic):
    at = open_live(mic)
    call = mic.calls[-1]
    assert call["rtc_configuration"] == {"iceServers": []}
    assert call["media_stream_constraints"] == {"audio": True, "video": False}
    assert call["mode"] == streamlit_webrtc.WebRtcMode.SENDONLY
    assert isinstance(call["sink_audio_track"], streamlit_webrtc.AudioSinkTrack)  # no frame dropped
    assert button(at, "live.stop").disabled  # nothing to stop yet
    assert any("Start" in shown(i.value) for i in at.info)


def test_talking_switching_controls_and_stop_give_a_whole_result(app_env, mic, speech48):
    mic.playing = True
    at = open_live(mic)
    frames = list(stereo_frames(speech48))
    for f in frames[:150]:  # 3 s of speech, through the callback the page gave the transport
        mic.callback(f)
    stage = at.session_state["live.stage"]
    assert stage.session.wait(APP_RUN_S)
    at.run()
    first = viewer(at, "live.skeleton")
    assert "free" in first["title"]
    assert any(m.label == "Microphone to figure" for m in at.metric)
    assert button(at, "live.control.left_hand=high").proto.type == "secondary"
    button(at, "live.control.left_hand=high").click().run()
    assert not at.exception, at.exception
    assert at.session_state["live.control"] == "left_hand=high"
    assert button(at, "live.control.left_hand=high").proto.type == "primary"
    switched_s = stage.session.view().frames / 15
    for f in frames[150:]:
        mic.callback(f)
    assert stage.session.wait(APP_RUN_S)
    at.run()
    later = viewer(at, "live.skeleton")
    assert "left_hand=high" in later["title"]
    button(at, "live.stop").click().run()
    assert not at.exception, at.exception
    record = at.session_state["gk.synthesis"]
    result = record["result"]
    assert result.n_frames == len(frames) * FRAME * 15 // RATE  # the whole speech streamed
    assert result.source == "live microphone"
    (segment,) = result.control.segments
    assert segment.label() == "left_hand=high" and segment.start_s == pytest.approx(switched_s, abs=1 / 15)
    # the performance and its downloads are on the page; the microphone is asked to close
    assert viewer(at, "live.result")["n_grid"] == result.n_frames
    keys = {d.key for d in at.get("download_button")}
    assert {"live.download_wav", "live.download_npz", "live.download_bvh"} <= keys
    assert mic.calls[-1]["desired_playing_state"] is False
    assert at.session_state["live.stage"].session is None


def test_stopping_the_stream_in_the_browser_is_stop_too_and_the_inspector_opens_it(app_env, mic, speech48):
    mic.playing = True
    at = open_live(mic)
    for f in list(stereo_frames(speech48))[:100]:
        mic.callback(f)
    assert at.session_state["live.stage"].session.wait(APP_RUN_S)
    mic.playing = False  # the component's own stop button
    at.run()
    assert not at.exception, at.exception
    result = at.session_state["gk.synthesis"]["result"]
    assert result.n_frames == 100 * FRAME * 15 // RATE
    button(at, "live.render").click().run()  # the MP4 with sound, then its download in the button's place
    assert not at.exception, at.exception
    assert "live.download_mp4" in {d.key for d in at.get("download_button")}
    assert at.session_state["_live.video"]["bytes"][4:8] == b"ftyp"  # an MP4
    at.switch_page("views/2_Retrieval_inspector.py").run()
    assert not at.exception, at.exception
    assert not any("Synthesize page first" in shown(i.value) for i in at.info)
    assert len(at.get("component_instance")) > 0  # the inspector's 3D views


def test_stop_after_too_little_speech_says_so_on_the_page(app_env, mic, speech48):
    mic.playing = True
    at = open_live(mic)
    for f in list(stereo_frames(speech48))[:2]:  # 40 ms: less than a frame of motion
        mic.callback(f)
    assert at.session_state["live.stage"].session.wait(APP_RUN_S)
    at.run()
    button(at, "live.stop").click().run()
    assert not at.exception, at.exception
    assert any("could not be kept" in shown(e.value) and "shorter than one frame" in shown(e.value) for e in at.error)
    assert "gk.synthesis" not in at.session_state
    assert mic.calls[-1]["desired_playing_state"] is False  # the microphone is closed all the same
    at.run()  # the panel's next refresh still says it
    assert any("shorter than one frame" in shown(e.value) for e in at.error)


# --- without a microphone --------------------------------------------------------------------------
def test_file_player_hands_the_speech_over_in_order_at_its_time(live):
    """Each 20 ms chunk is fed when its moment has come, in order; Stop halts it."""
    fed, waits = [], []
    now = [0.0]

    class Session:
        def feed(self, samples, rate, **_):
            fed.append((now[0], np.array(samples), rate))

    class Stage:
        def begin(self):
            return Session()

    def wait(seconds):
        waits.append(seconds)
        now[0] += seconds  # a clock that the wait moves on
        return False

    x = np.random.default_rng(0).uniform(-1, 1, 16000 + 123).astype(np.float32)
    player = live.FilePlayer(Stage(), x, 16000, clock=lambda: now[0], wait=wait)
    player.start()
    player._thread.join(10)
    assert not player.playing and player.position_s == pytest.approx(x.size / 16000)
    np.testing.assert_array_equal(np.concatenate([f[1] for f in fed]), x)
    assert {len(f[1]) for f in fed[:-1]} == {320}  # 20 ms at 16 kHz
    for i, (t, _, rate) in enumerate(fed):
        assert rate == 16000 and t == pytest.approx(i * 320 / 16000)  # real time, not faster
    with pytest.raises(ConfigError, match="no sound"):
        live.FilePlayer(Stage(), np.zeros(0, np.float32), 16000)


def test_a_browser_without_a_microphone_is_told_so_and_offered_a_file(app_env, mic):
    at = open_live(mic)
    at.session_state["live.devices"] = {"api": True, "microphones": 0, "secure": True}
    at.run()
    assert not at.exception, at.exception
    (warning,) = [shown(w.value) for w in at.warning if "microphone" in shown(w.value)]
    assert "No microphone was found" in warning and "Live from a file" in warning
    assert "NotFoundError" not in warning
    # nor a hint to press a Start that is not there: the hint points at the file player
    hints = [shown(i.value) for i in at.info]
    assert not any("Start" in h for h in hints) and any("Live from a file" in h for h in hints), hints
    calls = len(mic.calls)
    at.run()
    assert len(mic.calls) == calls  # no Start that would fail with the browser's own error
    at.session_state["live.devices"] = {"api": False, "microphones": 0, "secure": False}
    at.run()
    assert any("served over HTTPS or from this machine" in shown(w.value) for w in at.warning)


def test_live_from_a_file_streams_it_through_the_live_path_with_every_control(app_env, mic):
    import io
    import time

    import soundfile as sf

    take, _ = generate_demo_take(seconds=3.0, seed=91, name="speech")
    buf = io.BytesIO()
    sf.write(buf, take.audio, 16000, format="WAV")
    at = open_live(mic)
    at.file_uploader(key="live.file").set_value(("talk.wav", buf.getvalue(), "audio/wav")).run()
    button(at, "live.file_go").click().run()
    assert not at.exception, at.exception
    player = at.session_state["live.player"]
    assert player.playing and at.get("audio")  # the speech plays in the page too
    while player.position_s < 1.2:
        time.sleep(0.05)
    # any control, not only the left hand's, switches while it plays
    button(at, "live.control.speed=fast").click().run()
    assert at.session_state["live.control"] == "speed=fast"
    player._thread.join(10)
    at.session_state["live.stage"].session.wait()
    at.run()  # the panel sees the file's end: the page keeps the performance
    at.run()
    assert not at.exception, at.exception
    result = at.session_state["gk.synthesis"]["result"]
    assert result.n_frames == pytest.approx(3.0 * 15, abs=1)  # the whole file, streamed
    (segment,) = result.control.segments
    # held from the first step not yet searched when it was pressed (the search waits for 0.93 s of lookahead)
    assert segment.label() == "speed=fast" and 0.0 < segment.start_s < 2.5 and segment.end_s == pytest.approx(3.0)
    assert "live.download_wav" in {d.key for d in at.get("download_button")}
