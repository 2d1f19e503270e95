"""The matching database: its takes and clips, the control attributes, and any clip in 3D with its sound."""

from __future__ import annotations

import numpy as np
import pandas as pd
import streamlit as st

from gesturekit.app import display, sidebar, state
from gesturekit.control import ATTRIBUTE_UNITS
from gesturekit.database import MatchingDatabase
from gesturekit.motion import AUDIO_SR, Motion
from gesturekit.viz.figures import attribute_histograms, waveform_figure
from gesturekit.workspace import database_words

CLIP = "db.clip"  # the clip shown in the viewer (per user)
_LAST_ROW = "_db.last_selected_clip"  # the table selection already applied


def summary(db: MatchingDatabase) -> None:
    d = db.describe()
    st.subheader("Summary")
    cols = st.columns(5)
    cols[0].metric("Clips", f"{d['clips']}", help=f"{d['clip_frames']} frames each")
    cols[1].metric("Takes", f"{d['takes']}")
    cols[2].metric(
        "Minutes in clips", f"{d['minutes_in_clips']:.1f}", help=f"of {d['minutes_of_takes']:.1f} in the takes"
    )
    cols[3].metric("Frame rate", f"{d['fps']} fps")
    cols[4].metric("Audio", "stored" if d["has_audio"] else "none")
    st.markdown(
        f"**Label:** {display.escape_markdown(d['label'] or '(none)')}  \n"
        f"**Source:** {display.escape_markdown(d['source'] or '(unknown)')}  \n"
        f"**Database:** {display.escape_markdown(database_words(d['path']))}  \n"
        f"**Clip size:** {d['clip_frames']} frames = {d['clip_frames'] / d['fps']:.2f} s; "
        + ", ".join(f"{k} {v}" for k, v in d["feature_sizes"].items())
        + (f"; {d['overlap_windows']} overlapping windows for the refiner" if d["overlap_windows"] else "")
    )


def pick_clip(db: MatchingDatabase) -> int:
    """Takes and clips tables; a selected row or the number input picks the clip to view."""
    ss = st.session_state
    st.subheader("Takes")
    st.dataframe(
        db.takes_table(),
        hide_index=True,
        key="db.takes_table",
        column_config={"duration_s": st.column_config.NumberColumn("duration [s]", format="%.1f")},
    )

    st.subheader("Clips")
    takes = ["all takes"] + db.take_names
    fkey = state.persistent_key("db.take_filter", "all takes")
    if ss[fkey] not in takes:  # a take of another database
        ss[fkey] = "all takes"
    which = ss["db.take_filter"] = st.selectbox("Clips of", takes, key=fkey)
    table = db.clips_table()
    if which != "all takes":
        table = table[table["take"] == which].reset_index(drop=True)
    row = display.selected_row(
        table,
        key="db.clips_table",
        height=260,
        column_config={
            "start_s": st.column_config.NumberColumn("start [s]", format="%.2f"),
            "end_s": st.column_config.NumberColumn("end [s]", format="%.2f"),
        },
    )
    selected = None if row is None else int(table.iloc[row]["clip"])
    key = state.picked_key(CLIP, selected, last=_LAST_ROW, n=db.n_clips)  # another database may have fewer clips
    clip = st.number_input(
        "Clip to view",
        min_value=0,
        max_value=db.n_clips - 1,
        step=1,
        key=key,
        help="or select a row of the clips table",
    )
    ss[CLIP] = int(clip)
    return int(clip)


def clip_attributes(db: MatchingDatabase, clip: int) -> pd.DataFrame:
    """Each control attribute over the clip's frames, against the database's thresholds."""
    rows = []
    for name in db.attribute_names:
        v = np.asarray(db.attribute(name)[clip], dtype=np.float64)
        lo, hi = db.thresholds[name]
        rows.append(
            {
                "attribute": name,
                "unit": ATTRIBUTE_UNITS.get(name, ""),
                "clip mean": v.mean(),
                "low threshold": lo,
                "high threshold": hi,
                "frames low [%]": 100 * np.mean(v < lo),
                "frames high [%]": 100 * np.mean(v > hi),
            }
        )
    return pd.DataFrame(rows)


def viewer(db: MatchingDatabase, clip: int) -> None:
    clips = db.clips_table()
    row = clips.iloc[clip]
    st.subheader(f"Clip {clip}")
    st.caption(
        f"take **{display.escape_markdown(row['take'])}**, "
        f"frames {row['start_frame']}–{row['start_frame'] + db.clip_frames - 1} "
        f"({row['start_s']:.2f}–{row['end_s']:.2f} s)"
    )
    motion = Motion.from_flat(np.asarray(db.G[clip]), db.fps, db.joint_presence)
    audio = db.segment_audio(clip, 0, db.clip_frames) if db.audio is not None else None
    left, right = st.columns([3, 2])
    with left:
        display.show_skeletons(
            motion, title=f"clip {clip}: {row['take']} at {row['start_s']:.2f} s", key="db.skeleton", audio=audio
        )
    with right:
        if audio is not None:
            st.caption("▶ Play under the 3D view plays the clip's speech with it.")
            st.plotly_chart(waveform_figure(audio, AUDIO_SR, height=200), key="db.waveform")
        else:
            st.caption("This database was built without audio.")
    # the whole page's width: every column readable; mean and thresholds in the row's unit
    st.markdown(f"**Control attributes of clip {clip}**")
    st.dataframe(
        clip_attributes(db, clip),
        hide_index=True,
        key="db.clip_attributes",
        width="stretch",
        column_config={
            c: st.column_config.NumberColumn(format="%.3f") for c in ("clip mean", "low threshold", "high threshold")
        }
        | {c: st.column_config.NumberColumn(format="%.0f") for c in ("frames low [%]", "frames high [%]")},
    )


def main() -> None:
    st.title("Database")
    db = sidebar.sidebar_database()
    summary(db)
    clip = pick_clip(db)
    viewer(db, clip)
    st.subheader("Control attributes")
    st.caption(
        "How each attribute is distributed over all clip frames. Controls compare an attribute with "
        "its low and high thresholds: a 'low' control keeps frames left of the low line, 'high' right "
        "of the high line."
    )
    st.plotly_chart(attribute_histograms(db), key="db.histograms")


main()
