"""Speak into the microphone and watch the body gesture to it; switch a control while talking; Stop keeps it all."""

from __future__ import annotations

import functools
from typing import Any

import streamlit as st

from gesturekit import interactive as gs
from gesturekit.app import display, nav, resources, sidebar, state
from gesturekit.app import live_session as live
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.audio import wav_bytes
from gesturekit.errors import GestureKitError
from gesturekit.motion import AUDIO_SR, Motion
from gesturekit.synthesis import SynthesisConfig

STAGE = "live.stage"  # the user's LiveStage (microphone, current performance)
SINK = "live.sink"  # the transport's audio sink, feeding the stage
CONTROL = "live.control"  # the control asked for last (a constraint, or None: free)
SHOWN = "live.shown_run"  # the run number of the performance this page made last
_STOPPING = "_live.stopping"  # Stop was pressed: the next run asks the browser to close the stream
_BVH = "_live.bvh"  # (run, bytes or None, report or why no BVH) of the performance shown
_VIDEO = "_live.video"  # {"run": n, "bytes": mp4}
_FAILED = "_live.failed"  # why the last performance could not be kept (see finish)
PLAYER = "live.player"  # the FilePlayer of Live from a file (None: none began)
_FILE_AUDIO = "_live.file_audio"  # the speech it plays, also played in the browser
_NO_MIC = "_live.no_mic"  # the browser said it offers no microphone
#: Seconds between refreshes of the live figure and latency while the microphone is on. Each refresh
#: is a run of the panel on the server and a new view in the browser: faster refreshes, on a machine
#: whose cores are busy, delay the audio stream itself (measured on 2 shared cores: 0.2 s made the
#: stream arrive in bursts seconds late, 0.4 s kept it within a few hundred ms of real time).
REFRESH_S = 0.4
SOURCE = "live microphone"


def microphone(stage: live.LiveStage, *, stopping: bool) -> Any:
    """The browser's microphone, streamed to the server (streamlit-webrtc, audio only, send only).

    Returns its context (``.state.playing``). No STUN/TURN server is named unless
    ``$GESTUREKIT_ICE_SERVERS`` gives some: on 127.0.0.1 none is needed and nothing outside is
    contacted (``docs/guides/live.md``, "Live in the app", for serving to other machines).
    """
    from streamlit_webrtc import AudioSinkTrack, WebRtcMode, webrtc_streamer

    ss = st.session_state
    if SINK not in ss:
        # every frame, in order, handed to the stage on the transport's loop (a receiver's
        # bounded queue, or a frame callback processed apart, would drop frames under load)
        ss[SINK] = AudioSinkTrack(stage.on_frame)
    return webrtc_streamer(
        key="live.mic",
        mode=WebRtcMode.SENDONLY,
        sink_audio_track=ss[SINK],
        media_stream_constraints={"audio": True, "video": False},
        rtc_configuration=live.rtc_configuration(),
        desired_playing_state=False if stopping else None,
        translations={"start": "Start", "stop": "Stop microphone"},
    )


def microphones_found() -> dict | None:
    """What the browser offers (``api``: it can open a microphone at all; ``microphones``: how many
    it lists; ``secure``: the page is served so that browsers allow one), or None until it said."""
    value = display.microphones_component()(key="live.devices", default=None)
    return value if isinstance(value, dict) else None


def no_microphone_words(found: dict) -> str:
    """Why Start cannot work in this browser, in the page's words, with what to do instead."""
    if not found.get("api"):
        why = "This browser offers no microphone to web pages here" + (
            ": browsers allow one only on pages served over HTTPS or from this machine (127.0.0.1)."
            if not found.get("secure")
            else "."
        )
    else:
        why = "No microphone was found: none is connected, or the browser may not use it."
    return f"{why} Connect one and reload the page, or play a speech file through Live below (**Live from a file**)."


def file_player(stage: live.LiveStage, *, mic_on: bool) -> bool:
    """Live from a file: an uploaded speech streamed in real time through the same live path as the
    microphone, its sound played here. Returns whether a file is playing."""
    ss = st.session_state
    player: live.FilePlayer | None = ss.get(PLAYER)
    playing = player is not None and player.playing
    with st.expander("Live from a file", expanded=playing or ss.get(_NO_MIC, False)):
        st.caption(
            "Speech from a file, sent to the live synthesis as the microphone would send it: in real time, "
            "20 ms at a time. The control buttons switch it while it plays; **Stop** keeps it as a result."
        )
        upload = st.file_uploader(
            "Speech file", type=None, key="live.file", disabled=playing or mic_on, help="WAV, FLAC, OGG, MP3 ..."
        )
        if playing:
            st.caption(f"Playing {player.position_s:.1f} of {player.duration_s:.1f} s")
        if upload is not None and not playing and not mic_on:
            if st.button("Play through Live", key="live.file_go", type="primary"):
                with display.user_errors():
                    audio, _ = gs.read_speech_upload(upload.name, upload.getvalue())
                    stage.rearm()
                    player = ss[PLAYER] = live.FilePlayer(stage, audio, AUDIO_SR)
                    ss[_FILE_AUDIO] = audio
                    player.start()
                    playing = True
        if playing and _FILE_AUDIO in ss:
            st.audio(wav_bytes(ss[_FILE_AUDIO]), format="audio/wav", autoplay=True)
    return playing


def finish(stage: live.LiveStage) -> None:
    """Stop: the whole performance becomes the user's synthesis (downloads, Retrieval inspector).

    A performance that cannot be finished (too little speech, a failed search) leaves its
    message under :data:`_FAILED`, shown until the next performance begins (the live panel is
    redrawn several times a second, and a message drawn in it alone would vanish at once).
    """
    ss = st.session_state
    try:
        with st.spinner("Finishing the performance…"), display.warnings_shown():
            done = stage.stop()
    except GestureKitError as exc:
        ss[_FAILED] = f"The performance could not be kept: {display.error_text(exc)}"
        return
    if done is not None:
        result, db = done  # the database it began with, whatever the sidebar shows now
        ss[SHOWN] = state.keep_synthesis(db, result, source=SOURCE)["run"]


def control_buttons(stage: live.LiveStage) -> None:
    """Buttons that switch the control while talking; the one held now is shown as pressed."""
    ss = st.session_state

    def switch(constraint: str | None) -> None:  # before the panel is drawn again, so it shows the switch
        ss[CONTROL] = constraint
        stage.set_control(constraint)

    items = list(live.CONTROLS.items())
    per_row = 6
    cols = [c for a in range(0, len(items), per_row) for c in st.columns(per_row)]
    for col, (label, constraint) in zip(cols, items):
        held = ss.get(CONTROL) == constraint
        col.button(
            label,
            key=f"live.control.{constraint or 'free'}",
            type="primary" if held else "secondary",
            on_click=switch,
            args=(constraint,),
        )


def live_panel(db: MatchingDatabase, stage: live.LiveStage, playing: bool, from_file: bool = False) -> None:
    """The body as it is now, the latency, the control buttons and Stop (redrawn every :data:`REFRESH_S`)."""
    session = stage.session
    if session is not None:
        st.session_state.pop(_FAILED, None)  # a new performance: the last one's failure is old news
    elif _FAILED in st.session_state:
        st.error(display.escape_markdown(st.session_state[_FAILED]), icon=":material/error:")
    control_buttons(stage)
    view = session.view() if session is not None else None
    if session is not None and session.error:
        st.error(display.escape_markdown(session.error), icon=":material/error:")
    if view is None:
        if playing:
            hint = "Listening: the body moves once the first second of speech has arrived…"
        elif st.session_state.get(_NO_MIC):  # no Start to press: say where the body comes from instead
            hint = "Upload a speech file in **Live from a file** above and play it: the body appears here."
        else:
            hint = "Press **Start** above and allow the microphone; then speak."
        st.info(hint, icon=":material/mic:")
    else:
        title = f"speech {view.speech_s:.1f} s · frame {view.frame} · {view.control or 'free'}"
        made_with = session.db  # the sidebar may have changed since it began
        motion = Motion(view.positions[None], made_with.fps, made_with.joint_presence)
        display.show_skeletons(motion, key="live.skeleton", title=title, height=440)
        c = st.columns(3)
        c[0].metric(
            "Microphone to figure",
            f"{view.latency_s:.2f} s",
            help="from the moment a frame's speech was heard (its arrival at the server) to its drawing now",
        )
        c[1].metric(
            "Algorithmic delay",
            f"{view.algorithmic_s:.2f} s",
            help="speech the synthesis needs beyond a frame before the frame is determined",
        )
        c[2].metric("Compute per step", f"{view.compute_s * 1000:.0f} ms", help="resampling and the latest search")
    player = st.session_state.get(PLAYER)
    if from_file and player is not None and not player.playing:
        st.rerun()  # the file has ended: the whole page runs again and keeps the performance
    if st.button("Stop", type="primary", key="live.stop", disabled=session is None):
        finish(stage)
        st.session_state[_STOPPING] = True  # the next run asks the browser to close the microphone
        st.rerun()


def show_performance(record: dict) -> None:
    """The last performance: its 3D view with the speech, and the downloads."""
    ss = st.session_state
    result = record["result"]
    st.header("Performance")
    fps = result.motion.fps
    parts = [f"{result.n_frames} frames, {result.n_frames / fps:.1f} s"]
    if result.control:
        parts.append(f"controls: {display.escape_markdown(result.control.to_text(decimals=2))}")
    st.caption(" · ".join(parts))
    display.show_skeletons(result.motion, key="live.result", title=SOURCE, audio=result.audio, height=440)
    nav.link("Retrieval inspector")
    st.subheader("Downloads")

    def render(col) -> None:
        if col.button("Render MP4 with sound", key="live.render"):
            with st.spinner("Rendering…"), display.user_errors():
                ss[_VIDEO] = {"run": record["run"], "bytes": gs.render_mp4(result)}
                st.rerun()  # the download button in its place

    display.result_downloads(
        record, ("wav", "npz", "bvh", "csv"), prefix="live", keys=(_BVH, _VIDEO), before_video=render
    )


def main() -> None:
    st.title("Live")
    db = sidebar.sidebar_database()
    resources.warm_up(db)
    ss = st.session_state
    st.caption(
        "Speak into the microphone: the body gestures to your voice as you talk, about a second behind it "
        "(a step's speech feature looks 0.93 s ahead). Switch the controls while talking; **Stop** "
        "keeps the whole performance as a result: downloads here, and the Retrieval inspector."
    )
    stage: live.LiveStage = ss.setdefault(STAGE, live.LiveStage())
    stage.control = ss.get(CONTROL)
    stage.configure(lambda control: live.LiveSession(db, config=SynthesisConfig(), name=SOURCE, control=control))
    stopping = bool(ss.pop(_STOPPING, False))
    if stopping and ss.get(PLAYER) is not None:
        ss[PLAYER].stop()
    found = microphones_found()
    ss[_NO_MIC] = found is not None and (not found.get("api") or not found.get("microphones"))
    if ss[_NO_MIC]:  # say so in the page's words, rather than a Start that fails with the browser's
        st.warning(no_microphone_words(found), icon=":material/mic_off:")
        mic_on = False
    else:
        mic_on = bool(microphone(stage, stopping=stopping).state.playing)
    from_file = file_player(stage, mic_on=mic_on)
    playing = mic_on or from_file
    if not playing:
        if stage.session is not None:  # the stream was stopped (the browser's, or the file's end): Stop too
            finish(stage)
        stage.rearm()

    def panel() -> None:  # redrawn on its own: errors shown as on the rest of the page (display.run_page)
        display.run_page(functools.partial(live_panel, db, stage, playing, from_file))

    st.fragment(run_every=REFRESH_S if playing else None)(panel)()
    record = state.current_synthesis(db)
    if record is not None and record["run"] == ss.get(SHOWN):
        show_performance(record)


main()
