"""Speech in, gestures out: choose speech, draw controls, set the search, run, watch, download."""

from __future__ import annotations

import time

import numpy as np
import pandas as pd
import streamlit as st

from gesturekit import interactive as gs
from gesturekit.app import characters, display, resources, sidebar, state, timeline
from gesturekit.control import CONSTRAINT_CHOICES, ControlTrack, empty_segments
from gesturekit.control_lanes import (
    curve_span,
    ranges_frame,
    ranges_from_curve,
    ranges_from_track,
    replace_in_lane,
    track_from_ranges,
)
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.audio import wav_bytes
from gesturekit.errors import ConfigError, GestureKitError, collect_warnings
from gesturekit.motion import AUDIO_SR, n_audio_frames
from gesturekit.options import widget_limits
from gesturekit.search import SearchConfig, describe_steps
from gesturekit.skeleton import FPS
from gesturekit.synthesis import SynthesisConfig
from gesturekit.viz.figures import wrist_figure

_BVH = "_synth.bvh"  # (run, bytes or None, report or why no BVH) of the current result
_GLB = "_synth.glb"  # (run, bytes or None, report or why no glTF) of the current result
SPEECH = "synth.speech"  # the user's speech: {"name", "audio", "summary", "notes", "token"}
SEGMENTS = "synth.segments"  # the control table as the user last left it (DataFrame)
EDITOR = "synth.segments_editor"  # the data editor's widget key (see state.remount_key)
_BASE = "_synth.segments_base"  # the table the editor shows before the user's edits
_EDIT = "_synth.timeline_edit"  # the id of the timeline's last edit the table holds
_SHOWN = "_synth.timeline_ranges"  # the ranges of the table's last valid state: what the timeline shows
_FAILED = "_synth.failed_upload"  # (token, message) of an upload that could not be read
_DERIVED = "_synth.figures"  # figures of the current result: {"run": n, name: figure}
_VIDEO = "_synth.video"  # {"run": n, "bytes": mp4, "note": how long it took, "character": its token or None}

UPLOAD, EXAMPLE = "Upload a file", "Example speech"
# short enough for a laptop's column (tests/browser/test_browser_laptop.py); each option's help says the rest
_INIT_LABELS = {"random": "random frame (paper)", "rest": "rest pose"}
_BLEND_LABELS = {
    "dead": "dead blending (ours)",
    "inertialize": "inertialize (ours)",
    "offset": "offset fade (ours)",
    "none": "hard joins (paper)",
}
_MASK_LABELS = {"ends": "window ends (paper)", "all": "every frame"}


def _set_speech(token, name: str, audio: np.ndarray, summary: str, notes=()) -> None:
    ss = st.session_state
    ss[SPEECH] = {"token": token, "name": name, "audio": audio, "summary": summary, "notes": list(notes)}
    ss[state.PINS_KEY] = {}  # pins were chosen for other speech


def _use_example(label: str) -> None:
    audio = resources.example_audio(label)
    _set_speech(("example", label), label, audio, f"generated, {len(audio) / AUDIO_SR:.2f} s")


def speech_input() -> dict | None:
    """Upload or example; returns the user's speech, or None when there is none yet."""
    ss = st.session_state
    mode = ss["synth.mode"] = st.radio(
        "Speech",
        [UPLOAD, EXAMPLE],
        horizontal=True,
        label_visibility="collapsed",
        key=state.persistent_key("synth.mode", UPLOAD),
    )
    if mode == UPLOAD:
        up = st.file_uploader(
            "Speech file: wav, flac, ogg or mp3, any sample rate and channels",
            type=["wav", "flac", "ogg", "mp3"],
            key="synth.upload",
        )
        if up is not None:
            token = ("upload", up.file_id)
            failed = ss.get(_FAILED)
            if failed is not None and failed[0] == token:
                st.error(display.escape_markdown(failed[1]), icon=":material/error:")
                return _kept_speech()
            if ss.get(SPEECH, {}).get("token") != token:
                try:
                    with st.spinner("Reading the speech…"), collect_warnings() as notes:
                        audio, info = gs.read_speech_upload(up.name, up.getvalue())
                except (GestureKitError, OSError) as exc:
                    # remembered, so the same upload is not decoded again on every rerun
                    ss[_FAILED] = (token, display.error_text(exc))
                    st.error(display.escape_markdown(ss[_FAILED][1]), icon=":material/error:")
                    return _kept_speech()
                _set_speech(token, up.name, audio, info.summary(), notes)
        elif SPEECH not in ss:
            # a first visit opens on an example, so the whole page can be seen and run at once
            # (and the browser has its charts and table ready when the user's file arrives)
            _use_example(next(iter(gs.SPEECH_EXAMPLES)))
        if up is None and ss[SPEECH]["token"][0] == "example":
            st.caption("Until you upload a file, the page works on example speech.")
    else:
        labels = list(gs.SPEECH_EXAMPLES)
        key = state.persistent_key("synth.example", labels[0])
        label = ss["synth.example"] = st.selectbox(
            "Example", labels, key=key, help="new speech of the generated demo speaker, not in the database"
        )
        if ss.get(SPEECH, {}).get("token") != ("example", label):
            _use_example(label)
    return ss.get(SPEECH)


def _kept_speech() -> dict | None:
    """After an upload that could not be read: the user's previous upload stays the speech (the
    error is shown above it); the example speech does not stand in for a file the user chose."""
    speech = st.session_state.get(SPEECH)
    if speech is not None and speech["token"][0] == "upload":
        st.caption(f"Still working on **{display.escape_markdown(speech['name'])}**, the last file that could be read.")
        return speech
    return None


def _editor_base(key: str) -> pd.DataFrame:
    ss = st.session_state
    if key not in ss or _BASE not in ss:
        # a new editor (first visit, or not drawn in the last run: another page, or the page
        # stopped in the sidebar): it starts again from the table as the user left it
        ss[_BASE] = ss.get(SEGMENTS, empty_segments())
    return ss[_BASE]


def _replace_table(table: pd.DataFrame) -> None:
    """Give the editor a new table (its edits so far are part of ``table``) and redraw."""
    ss = st.session_state
    ss[_BASE] = ss[SEGMENTS] = table
    st.rerun()


def controls(speech: dict, db: MatchingDatabase) -> ControlTrack | None:
    """The control timeline under the speech, the same ranges as a table below it; returns the track (None if
    the table is invalid)."""
    ss = st.session_state
    timeline_slot = st.container()  # drawn after the table, so it shows the latest edits
    key = state.remount_key(EDITOR)
    table = st.data_editor(
        _editor_base(key),
        key=key,
        num_rows="dynamic",
        hide_index=True,
        width="stretch",
        column_config={
            "start_s": st.column_config.NumberColumn(
                "start [s]", min_value=0.0, step=0.01, format="%.2f", required=True
            ),
            "end_s": st.column_config.NumberColumn("end [s]", min_value=0.0, step=0.01, format="%.2f", required=True),
            "constraint": st.column_config.SelectboxColumn(
                "constraint", options=list(CONSTRAINT_CHOICES), required=True
            ),
        },
    )
    ss[SEGMENTS] = table
    track, problem = None, None
    try:
        track = track_from_ranges(table)
    except ConfigError as exc:
        problem = str(exc)
    if track is not None:
        ss[_SHOWN] = ranges_from_track(track)
    segment = int(ss.get("synth.segment", _limits("segment", db)["default"]))
    with timeline_slot:
        st.caption(
            "Drag in a lane to paint a control over a stretch of the speech; pick its level beside the lane's "
            "name. Drag a range to move it, its edges to resize it; it snaps to the search's steps "
            f"(N = {segment} frames, {segment / FPS:.2f} s). Click a range to select it: Delete removes it, "
            "← → move it a step, Ctrl+Z undoes. ∿ draws a curve in a lane instead. Where lanes overlap, "
            "all their controls hold."
        )
        value = timeline.control_timeline(
            speech["audio"],
            ss.get(_SHOWN, []),
            thresholds=db.thresholds,
            step_s=segment / FPS,
            edit=ss.get(_EDIT),
            key="synth.timeline",
        )
    if value is not None and value.get("edit") != ss.get(_EDIT):
        ss[_EDIT] = value.get("edit")
        with display.user_errors():
            rows = _with_curve(timeline.rows_of(value), value.get("curve"), speech, db, segment)
            _replace_table(ranges_frame(track_from_ranges(rows)))
    cols = st.columns([1, 4])
    if cols[0].button("Clear segments", key="synth.clear_segments", disabled=table.empty):
        _replace_table(empty_segments())
    cols[1].caption(
        "The table holds the timeline's ranges, one row each: edit, add or delete rows here as well. "
        "Low/high compare with the database's percentile thresholds (see the Database page)."
    )
    if problem:
        st.error(display.escape_markdown(problem), icon=":material/error:")
    return track


def _with_curve(rows: list[dict], curve: dict | None, speech: dict, db: MatchingDatabase, segment: int) -> list[dict]:
    """The timeline's rows with a curve just drawn in a lane turned into that lane's ranges, step by step,
    where the curve was drawn (``docs/guides/controls.md``, "A drawn curve")."""
    if not curve:
        return rows
    n_frames = n_audio_frames(len(speech["audio"]))
    times = np.asarray(curve.get("t", []), dtype=np.float64)
    span = curve_span(times, n_frames=n_frames, segment=segment)
    if span is None:
        return rows
    new = ranges_from_curve(
        str(curve.get("lane")),
        times,
        np.asarray(curve.get("y", []), dtype=np.float64),
        thresholds=db.thresholds,
        n_frames=n_frames,
        segment=segment,
    )
    return replace_in_lane(rows, str(curve.get("lane")), new, start_s=span[0], end_s=span[1])


#: The configuration class that declares each option the page sets (its field metadata: bounds, default, help).
OPTION_CLASS = {
    "k": SearchConfig,
    "segment": SearchConfig,
    "seed": SearchConfig,
    "record": SearchConfig,
    "mask_rule": SearchConfig,
    "init": SynthesisConfig,
    "blend": SynthesisConfig,
    "refiner_keep_hz": SynthesisConfig,
}


def _limits(name: str, db: MatchingDatabase) -> dict:
    """The widget limits of the option ``name`` (``db``: bounds that depend on the database)."""
    return widget_limits(OPTION_CLASS[name], name, context=db)


def _number(col, label: str, name: str, db: MatchingDatabase, **options):
    """A number input of the option ``name``, its bounds, step, default and help from its field."""
    lim = _limits(name, db)
    key = state.persistent_key(f"synth.{name}", lim["default"])
    return col.number_input(
        label, min_value=lim["min"], max_value=lim["max"], step=lim["step"], key=key, help=lim["help"], **options
    )


def _choice(col, label: str, name: str, db: MatchingDatabase, labels: dict):
    """A select box of the option ``name``, its choices and default from its field."""
    lim = _limits(name, db)
    key = state.persistent_key(f"synth.{name}", lim["default"])
    return col.selectbox(label, lim["choices"], format_func=lambda m: labels.get(m, m), key=key, help=lim["help"])


def settings(db: MatchingDatabase) -> dict:
    """The search settings: SynthesisConfig arguments, the refiner's checked folder (or None), and whether they can
    run."""
    ss = st.session_state
    pk = state.persistent_key
    segment_key = pk("synth.segment", _limits("segment", db)["default"])
    if ss[segment_key] > db.clip_frames:  # a database of shorter clips: say so, never change it unseen
        st.warning(
            f"N was {ss[segment_key]}, more than this database's clips hold ({db.clip_frames} frames): "
            f"it is now {db.clip_frames}.",
            icon=":material/warning:",
        )
        ss[segment_key] = ss["synth.segment"] = db.clip_frames
    c = st.columns(4)
    out = {
        "k": _number(c[0], "k (0 = best match)", "k", db),
        "segment": _number(c[1], "N (frames per step)", "segment", db),
        "seed": _number(c[2], "Seed", "seed", db),
        "record": _number(c[3], "Candidates recorded per step", "record", db),
    }
    c = st.columns(4)
    out["init"] = _choice(c[0], "Initial pose", "init", db, _INIT_LABELS)
    out["blend"] = _choice(c[1], "Blending", "blend", db, _BLEND_LABELS)
    out["mask_rule"] = _choice(c[2], "A control must hold at", "mask_rule", db, _MASK_LABELS)
    for name, value in out.items():
        ss[f"synth.{name}"] = value
    refiner, ok = None, True
    default = resources.default_refiner(db)
    on = ss["synth.refine"] = c[3].toggle(
        "Refiner (cGAN)",
        key=pk("synth.refine", bool(default)),
        help="smooth and re-time the k-NN motion with a trained refiner",
    )
    folder = ss["synth.refiner_path"] = c[3].text_input(
        "Refiner folder",
        key=pk("synth.refiner_path", default),
        disabled=not on,
        placeholder="folder written by gesturekit train-refiner",
    )
    out["refiner_keep_hz"] = ss["synth.refiner_keep_hz"] = _number(
        c[3], "Keep k-NN motion below (Hz)", "refiner_keep_hz", db, disabled=not on
    )
    if on:
        ok = False  # until the refiner is checked: a run must not silently go without it
        with display.user_errors():
            # config and layout only here (no torch); the weights load when Run is pressed
            refiner = resources.check_refiner(folder, db)
            ok = True
    differs = _paper_differences(out, refined=on)
    if differs:
        st.caption("Differs from the paper: " + "; ".join(differs))
    return {"options": out, "refiner": refiner, "ok": ok}


def _refiner_name(made_by: dict) -> str:
    """What the page calls a refiner: the shipped demo refiner, or its folder's name (never the server's path)."""
    from pathlib import Path

    from gesturekit.refine import default_refiner_path

    path = Path(str(made_by.get("path", "")))
    if path == default_refiner_path():
        return "the demo refiner"
    return f"the refiner {path.name}" if path.name else "a refiner"


def _paper_differences(options: dict, *, refined: bool) -> list[str]:
    try:
        return SynthesisConfig(**options).paper_differences(refined=refined)
    except ConfigError:  # an impossible setting is reported when Run is pressed
        return []


def _figure(record, name: str, build):
    """A figure of the current result, made once per result (reruns reuse it)."""
    ss = st.session_state
    cache = ss.get(_DERIVED)
    if cache is None or cache["run"] != record["run"]:
        cache = ss[_DERIVED] = {"run": record["run"]}
    if name not in cache:
        cache[name] = build()
    return cache[name]


def video(record: dict) -> None:
    """The MP4 with sound, rendered on demand on every core, then played in the page."""
    ss = st.session_state
    result = record["result"]
    done = ss.get(_VIDEO)
    token = characters.character_token()
    full = st.checkbox(
        "Full-body MP4",
        key="synth.video_full_body",
        help="frame the MP4 on the whole person down to the floor (default: the upper body and every hand)",
    )
    framing = "full body" if full else "upper body"
    if done is not None and (done.get("character"), done.get("framing")) != (token, framing):  # made again
        ss.pop(_VIDEO)
        done = None
    if done is not None and done["run"] == record["run"]:
        st.video(done["bytes"], format="video/mp4")
        st.caption(done["note"])
        return
    st.caption("For exact audio-video sync, render the motion offscreen to an MP4 with the speech as soundtrack.")
    if st.button("Render MP4 with sound", key="synth.render"):
        from gesturekit.viz.render_pool import default_workers  # the rendering libraries load only when rendering

        workers = default_workers()
        bar = st.progress(0.0, text=f"rendering on {workers} core{'s' if workers > 1 else ''}…")
        shown = {"at": 0.0, "frames": 0}

        def progress(i: int, n: int) -> None:
            # a few updates a second: one message per frame would keep the browser busy redrawing the bar
            now, shown["frames"] = time.perf_counter(), n
            if i == n or now - shown["at"] >= 0.2:
                shown["at"] = now
                bar.progress(min(1.0, i / max(n, 1)), text=f"rendering frame {i} / {n}")

        t0 = time.perf_counter()
        try:
            data = characters.render_mp4(result, progress=progress, framing=framing)  # on the user's character, if any
        except GestureKitError as exc:
            bar.empty()
            st.error(f"Could not render the video: {display.escape_markdown(exc)}")
            return
        seconds = time.perf_counter() - t0
        bar.empty()
        frames = shown["frames"]
        note = (
            f"Rendered {frames} frames in {seconds:.1f} s ({frames / max(seconds, 1e-9):.0f} frames/s); "
            "download it below."
        )
        ss[_VIDEO] = {"run": record["run"], "bytes": data, "note": note, "character": token, "framing": framing}
        st.video(data, format="video/mp4")
        st.caption(note)


def show_result(db: MatchingDatabase, record: dict) -> None:
    result = record["result"]
    st.header("Result")
    c = result.config
    parts = [f"k = {c.k}", f"N = {c.segment}", f"seed {c.seed}", f"initial pose: {c.init}", f"blend: {c.blend}"]
    if result.control:
        parts.append(f"controls: {display.escape_markdown(result.control.to_text(decimals=2))}")
    if c.pins:
        parts.append(f"{len(c.pins)} pinned step{'s' if len(c.pins) > 1 else ''}")
    if result.refined_motion is not None:
        made_by = getattr(result, "refiner", None)
        parts.append(f"refined by {display.escape_markdown(_refiner_name(made_by))}" if made_by else "refined")
    differs = c.paper_differences(refined=result.refined_motion is not None)
    if differs:
        parts.append("differs from the paper: " + "; ".join(differs))
    st.caption(" · ".join(parts))
    if result.relaxed_steps:
        where = describe_steps(result.relaxed_steps, segment=c.segment, fps=result.motion.fps)
        st.warning(
            f"No database window satisfied the control at {where}; the control was dropped there.",
            icon=":material/warning:",
        )
    motions, labels = gs.display_motions(result)
    labels = labels if len(motions) > 1 else None
    # side by side, the characters take the page's width (in a column, two presenters would be a quarter of its
    # height); a lone character shares the row with the speech's controls
    left, right = st.columns([3, 2]) if len(motions) == 1 else (st.container(), st.container())
    with left:
        title = f"{result.source}: {result.n_frames} frames, {result.n_frames / result.motion.fps:.1f} s"
        # sent before the wrist plot is made, so the browser draws the 3D view meanwhile
        display.show_skeletons(
            motions,
            labels=labels,
            title=title,
            key="synth.skeleton",
            audio=result.audio,
            character=characters.current_character(),
        )
    with right:
        st.markdown("**Speech**")
        st.caption(
            "▶ Play under the 3D view plays the speech, and the view follows it frame by frame; or render the video:"
        )
        video(record)
    st.subheader("Wrist height and speed")
    st.caption("Shaded: the control segments. Dashed: the database's low and high thresholds of each quantity.")
    wrists = _figure(
        record, "wrists", lambda: wrist_figure(motions, labels=labels, bands=result.control, thresholds=db.thresholds)
    )
    st.plotly_chart(wrists, key="synth.wrists", config={"displaylogo": False})

    st.subheader("Downloads")
    display.result_downloads(
        record,
        ("npz", "bvh", "glb", "wav", "csv", "json"),
        prefix="synth",
        keys=(_BVH, _VIDEO),
        before_video=lambda col: col.caption("MP4: render it above"),
        glb_key=_GLB,
    )
    characters.character_downloads(record, prefix="synth")


def main() -> None:
    st.title("Synthesize")
    db = sidebar.sidebar_database()
    resources.warm_up(db)
    ss = st.session_state

    st.subheader("1 · Speech")
    speech = speech_input()
    if speech is None:
        st.info("Upload a speech file, or choose an example.")
        record = state.current_synthesis(db)
        if record is not None:  # the last result stays in view
            show_result(db, record)
        return
    st.caption(f"**{display.escape_markdown(speech['name'])}** · {display.escape_markdown(speech['summary'])}")
    for note in speech["notes"]:
        st.warning(display.escape_markdown(note), icon=":material/warning:")
    st.audio(wav_bytes(speech["audio"]), format="audio/wav")

    st.subheader("2 · Controls")
    track = controls(speech, db)

    st.subheader("3 · Search")
    chosen = settings(db)
    record = state.current_synthesis(db)
    if record is None:
        ss[state.PINS_KEY] = {}  # pins name clips of the database of the last result
    pins = dict(ss.get(state.PINS_KEY, {}))
    if pins:
        c = st.columns([4, 1])
        c[0].caption(
            "Pinned choices from the Retrieval inspector (step: clip, start): "
            + ", ".join(f"{i}: {m}, {s}" for i, (m, s) in sorted(pins.items()))
        )
        if c[1].button("Clear pins", key="synth.clear_pins"):
            ss[state.PINS_KEY] = {}
            st.rerun()
    if st.button("Run", type="primary", key="synth.go", disabled=track is None or not chosen["ok"]):
        with display.user_errors():  # an impossible setting is reported; the last result stays below
            config = SynthesisConfig(**chosen["options"], control=track, pins=pins)
            refiner = None if chosen["refiner"] is None else resources.load_refiner(chosen["refiner"], db)
            state.run_synthesis(db, speech["audio"], config=config, source=speech["name"], refiner=refiner)

    record = state.current_synthesis(db)
    if record is not None:
        show_result(db, record)
    elif ss.get(state.SYNTHESIS_KEY) is not None:
        st.info("The last result was made with another database; run again.")


main()
