"""Step through the search: each step's candidates, their distances and clips; pin a choice; compare k."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import streamlit as st

from gesturekit import interactive as gs
from gesturekit.app import characters, display, nav, sidebar, state
from gesturekit.character import look
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.audio import wav_bytes
from gesturekit.motion import AUDIO_SR
from gesturekit.synthesis import SynthesisResult
from gesturekit.viz.figures import candidates_figure, waveform_figure, wrist_figure
from gesturekit.viz.paper import FORMATS, figure_bytes, filmstrip_figure
from gesturekit.viz.retrieval import candidate_figure, candidates_strip

STEP = "inspect.step"  # the step shown (per user)
CANDIDATE = "inspect.candidate"  # the position of the candidate inspected at that step
COMPARE = "inspect.compare"  # {"run": n, "ks": [...], "results": [...]}
_LAST_ROW = "_inspect.last_selected_step"  # the steps-table selection already applied
_LAST_PICKS = "_inspect.last_picks"  # the candidate selections already applied, per place
TABLE_KEY, SCATTER_KEY, STRIP_KEY = "inspect.candidates", "inspect.candidates_plot", "inspect.strip"
CONTEXT_S = 1.0  # seconds of a candidate's take heard around it

_n, _t = st.column_config.NumberColumn, st.column_config.TextColumn
#: Every column of the page's tables, named in words (ranks count from 0, the best).
CANDIDATE_COLUMNS = {
    "position": _n("combined position"),
    "clip": _n("clip"),
    "start": _n("start frame"),
    "take": _t("take"),
    "source_s": _n("source time [s]", format="%.2f"),
    "pose_dist": _n("pose distance", format="%.3f"),
    "audio_dist": _n("audio distance", format="%.4f"),
    "pose_rank": _n("pose rank"),
    "audio_rank": _n("audio rank"),
    "combined": _n("combined rank"),
    "chosen": st.column_config.CheckboxColumn("chosen"),
}
STEPS_COLUMNS = {
    "step": _n("step"),
    "first_frame": _n("first frame"),
    "start_s": _n("time [s]", format="%.2f"),
    "clip": _n("clip"),
    "start": _n("start frame"),
    "take": _t("take"),
    "source_s": _n("source time [s]", format="%.2f"),
    "position": _n("combined position"),
    "candidates": _n("clips that survived"),
    "relaxed": st.column_config.CheckboxColumn("control relaxed"),
    "pinned": st.column_config.CheckboxColumn("pinned"),
}
COMPARE_COLUMNS = {
    "k": _n("k"),
    "pose_dist": _n("mean pose distance", format="%.3f"),
    "audio_dist": _n("mean audio distance", format="%.4f"),
    "relaxed_steps": _n("steps relaxed"),
    "pinned_steps": _n("steps pinned"),
    "control_met": _n("control met", format="%d%%"),
}


def _rerun_with(db, record, config) -> None:
    """Synthesise again with new pins (everything else as before) and redraw."""
    result = record["result"]
    state.run_synthesis(db, result.audio, config=config, source=result.source, refiner=record["refiner"])
    st.rerun()


def pick_step(db: MatchingDatabase, result: SynthesisResult) -> int:
    """The steps table (a selected row picks the step) and the step number input."""
    ss = st.session_state
    table = result.steps_overview(db)
    with st.expander(f"All {len(table)} steps", expanded=False):
        selected = display.selected_row(table, key="inspect.steps_table", height=240, column_config=STEPS_COLUMNS)
    key = state.picked_key(STEP, selected, last=_LAST_ROW, n=len(table))  # a new result may have fewer steps
    step = st.number_input(
        "Step", min_value=0, max_value=len(table) - 1, step=1, key=key, help="or select a row of the steps table"
    )
    ss[STEP] = int(step)
    return int(step)


def _clicked(event: Any) -> list[dict]:
    """The points of a plotly chart's selection event (an empty list without one)."""
    try:
        return list(event["selection"]["points"])
    except (KeyError, TypeError):
        return []


def _custom(point: dict) -> list[int]:
    """A clicked point's ``customdata`` as integers: the browser sends a list, or an object
    keyed "0", "1", ... for a trace whose customdata is a typed array."""
    data = point.get("customdata")
    if isinstance(data, dict):
        data = [data[k] for k in sorted(data, key=int)]
    try:
        return [int(v) for v in data] if isinstance(data, list) else []
    except (TypeError, ValueError):
        return []


def _selected_rows(event: Any) -> list[int]:
    try:
        return [int(r) for r in event["selection"]["rows"]]
    except (KeyError, TypeError):
        return []


def sync_candidate(step: int, table: Any) -> int:
    """The candidate looked at closely: the chosen one when a step is shown, then the last one
    selected anywhere (a row of the candidates table, a point of the scatter, a candidate of the
    strip, or the selectbox); every place then shows that one selected.

    ``table``: the step's candidates table (rows best first). Returns its ``position``.
    """
    ss = st.session_state
    positions = [int(p) for p in table["position"]]
    by_window = {(int(r.clip), int(r.start)): int(r.position) for r in table.itertuples()}
    chosen = [int(p) for p, c in zip(table["position"], table["chosen"]) if c]
    windows = [tuple(_custom(p)[:2]) for p in _clicked(ss.get(SCATTER_KEY))]
    picks = {
        "table": [positions[r] for r in _selected_rows(ss.get(TABLE_KEY)) if 0 <= r < len(positions)],
        "scatter": [by_window[w] for w in windows if w in by_window],
        "strip": [c[0] for c in (_custom(p) for p in _clicked(ss.get(STRIP_KEY))) if c and c[0] in positions],
    }
    seen = ss.get(_LAST_PICKS)
    widget = state.persistent_key(CANDIDATE, chosen[0] if chosen else positions[0])
    if seen is None or seen.get("step") != step:  # a new step (or result): its chosen candidate
        ss[widget] = chosen[0] if chosen else positions[0]
    else:
        for source, picked in picks.items():
            if picked and picked != seen.get(source):
                ss[widget] = picked[0]
    ss[_LAST_PICKS] = {"step": step, **picks}
    if ss[widget] not in positions:
        ss[widget] = chosen[0] if chosen else positions[0]
    ss[CANDIDATE] = int(ss[widget])
    return int(ss[widget])


def step_view(db: MatchingDatabase, record: dict, step: int) -> None:
    ss = st.session_state
    result = record["result"]
    s, N, fps = result.search, result.config.segment, result.motion.fps
    a, b = step * N, min((step + 1) * N, result.n_frames)
    overview = result.steps_overview(db).iloc[step]
    flags = (" · **pinned**" if s.pinned[step] else "") + (" · control relaxed" if s.relaxed[step] else "")
    st.markdown(
        f"**Step {step}** · output frames {a}–{b - 1} ({a / fps:.2f}–{b / fps:.2f} s) · "
        f"chosen: clip {int(s.clip[step])} from frame {int(s.start[step])} "
        f"(take **{display.escape_markdown(overview['take'])}** at {overview['source_s']:.2f} s){flags} · "
        f"{int(s.n_candidates[step])} clips survived"
    )
    table = result.search.candidates_table(step, db)
    pick = sync_candidate(step, table)
    row_of = {int(r.position): r for r in table.itertuples()}
    r = row_of[pick]

    why_view(db, result, step, table, pick)
    st.dataframe(
        table,
        hide_index=True,
        key=TABLE_KEY,
        column_config=CANDIDATE_COLUMNS,
        on_select="rerun",
        selection_mode="single-row",
    )

    views, plot = st.columns([3, 2])
    with plot:
        names = [f"{r.take} at {r.source_s:.2f} s" for r in table.itertuples()]
        names += [""] * (s.cand_clip.shape[1] - len(names))
        st.plotly_chart(
            candidates_figure(s, step, names=names, height=300, selected=pick),
            key=SCATTER_KEY,
            config={"displaylogo": False},
            on_select="rerun",
            selection_mode="points",
        )
        st.caption("Click a point, a row of the table or a candidate in the strip to look at it closely.")
    with views:
        # one candidate at a time, framed as a presenter (the page's one framing rule): the one selected in the
        # table, the plot, the strip or the Candidate box below, at first the chosen one
        if r.chosen:
            motion = gs.candidate_motion(db, int(s.clip[step]), int(s.start[step]), b - a)
            what, scheme = f"#{pick} · chosen" + (" (pinned)" if s.pinned[step] else ""), look.role_scheme("chosen")
        else:
            motion = gs.candidate_motion(db, r.clip, r.start, b - a)
            what, scheme = f"#{pick} · selected", look.rank_scheme(pick)
        # the step's input speech is the clock: it is what every candidate was matched against
        display.show_skeletons(
            [motion],
            title=what,
            height=360,
            key="inspect.views",
            audio=gs.step_speech(result, step),
            character=characters.current_character(),
            schemes=[scheme],
        )
        st.caption("In 3D: the selected candidate. Select another in the table, the plot, the strip or below.")

    st.markdown("**Listen and choose**")
    positions = [int(p) for p in table["position"]]
    pick = ss[CANDIDATE] = st.selectbox(
        "Candidate",
        positions,
        key=state.persistent_key(CANDIDATE, pick),
        format_func=lambda p: (
            f"#{p}: clip {row_of[p].clip} from frame {row_of[p].start} "
            f"({row_of[p].take} at {row_of[p].source_s:.2f} s)" + (" · chosen" if row_of[p].chosen else "")
        ),
    )
    r = row_of[pick]
    c = st.columns(3)
    with c[0]:
        st.caption("the input speech of this step: ▶ Play in the 3D view above plays it with the candidates")
    with c[1]:
        st.caption(f"candidate #{pick}'s own speech in the database")
        if db.audio is not None:
            st.audio(wav_bytes(db.segment_audio(r.clip, r.start, b - a)), format="audio/wav")
            context(db, r, b - a)
        else:
            st.caption("(this database was built without audio)")
    with c[2]:
        if st.button(
            "Use this candidate instead",
            key="inspect.use",
            disabled=bool(r.chosen),
            type="primary",
            help="pin it at this step and run the synthesis again; later steps continue from it",
        ):
            _rerun_with(db, record, result.config.with_pin(step, r.clip, r.start))


def why_view(db: MatchingDatabase, result: SynthesisResult, step: int, table: Any, pick: int) -> None:
    """One candidate large (its whole clip, the window marked, beside the step's speech) over a
    strip of every candidate; each drawn over the query pose's ghost with its wrist paths."""
    views = gs.candidate_views(db, result, step)
    query = gs.query_pose(db, result, step)
    view = next(v for v in views if v.position == pick)
    what = "chosen" if view.chosen else "selected"
    st.markdown(
        f"**Why this clip?** Candidate **#{pick}** ({what}): "
        f"pose distance {view.pose_dist:.3f} to the query pose, audio distance {view.audio_dist:.4f} "
        "to this step's speech. "
        + (
            "The grey ghost is the query pose: the last frame of the previous step's window, which every "
            "candidate's first frame is compared with."
            if query is not None
            else "Step 0 starts from an initial pose given by its features, not a database frame: no ghost."
        )
    )
    st.plotly_chart(
        candidate_figure(
            view,
            query,
            fps=db.fps,
            clip_audio=gs.clip_speech(db, int(table.loc[table["position"] == pick, "clip"].iloc[0])),
            speech=gs.step_speech(result, step),
            title=f"#{pick} · {view.label}",
            height=400,
        ),
        key="inspect.candidate_large",
        config={"displaylogo": False},
    )
    st.plotly_chart(
        candidates_strip(views, query, selected=pick),
        key=STRIP_KEY,
        config={"displaylogo": False},
        on_select="rerun",
        selection_mode="points",
    )


def context(db: MatchingDatabase, r: Any, n_frames: int) -> None:
    """The candidate's speech with a second of its take on either side, the window shaded.

    ``r``: a row of the candidates table (``clip``, ``start``, ``take``).
    """
    audio, a, b, t0 = gs.segment_in_context(db, r.clip, r.start, n_frames, context_s=CONTEXT_S)
    st.caption(
        f"…with up to {CONTEXT_S:g} s around it: the window is {a:.2f}–{b:.2f} s of this "
        f"{len(audio) / AUDIO_SR:.2f} s excerpt ({display.escape_markdown(r.take)} at {t0 + a:.2f}–{t0 + b:.2f} s)"
    )
    st.audio(wav_bytes(audio), format="audio/wav")
    fig = waveform_figure(audio, AUDIO_SR, bands=[(a, b, "window")], height=150)
    fig.update_layout(showlegend=False, margin=dict(l=10, r=10, t=25, b=10), yaxis_title=None)
    st.plotly_chart(fig, key="inspect.context", config={"displaylogo": False})


def pins_view(db: MatchingDatabase, record: dict) -> None:
    result = record["result"]
    pins = result.config.pins
    st.subheader("Pins")
    if not pins:
        st.caption("No pinned step: every step took the k-th best candidate.")
        return
    for i, (clip, start) in pins.items():
        take = db.take_names[int(db.clip_take[clip])]
        c = st.columns([4, 1])
        c[0].markdown(
            f"step **{i}**: clip {clip} from frame {start} ({display.escape_markdown(take)} at "
            f"{(int(db.clip_start[clip]) + start) / db.fps:.2f} s)"
        )
        if c[1].button("Remove", key=f"inspect.unpin_{i}"):
            _rerun_with(db, record, result.config.without_pin(i))
    if len(pins) > 1 and st.button("Remove all pins", key="inspect.unpin_all"):
        config = result.config
        for i in list(pins):
            config = config.without_pin(i)
        _rerun_with(db, record, config)


def compare_view(db: MatchingDatabase, record: dict) -> None:
    ss = st.session_state
    result = record["result"]
    st.subheader("Compare k")
    st.caption("The same speech, controls, pins and seed, taking the k-th best candidate at every step.")
    ks = ss["inspect.ks"] = st.multiselect("k", list(range(10)), key=state.persistent_key("inspect.ks", [0, 1, 2]))
    if st.button("Compare", key="inspect.compare_go", disabled=not ks):
        with st.spinner("Searching…"):
            results = gs.compare_k(
                result.audio,
                db=db,
                config=result.config,
                ks=sorted(ks),
                refiner=record["refiner"],
                source=result.source,
            )
        ss[COMPARE] = {"run": record["run"], "ks": sorted(ks), "results": results}
    done = ss.get(COMPARE)
    if done is None or done["run"] != record["run"]:
        return
    motions = [r.refined_motion if r.refined_motion is not None else r.motion for r in done["results"]]
    labels = [f"k = {k}" for k in done["ks"]]
    display.show_skeletons(
        motions,
        labels=labels,
        height=420,
        key="inspect.compare_views",
        audio=result.audio,
        character=characters.current_character(),
        schemes=[look.rank_scheme(k) for k in done["ks"]],
    )
    table = gs.comparison_table(done["results"], db.thresholds)
    table["control_met"] = (100 * table["control_met"]).round()  # whole percent, one format for every row
    st.dataframe(table, hide_index=True, key="inspect.compare_table", column_config=COMPARE_COLUMNS)
    st.markdown(control_words(result.config.search.mask_rule))
    duration = max(m.duration for m in motions)
    default = (0.0, round(min(duration, 10.0), 2))
    zoom = ss["inspect.zoom"] = st.slider(
        "Time range shown [s]",
        min_value=0.0,
        max_value=round(duration, 2),
        step=0.1,
        key=state.persistent_key("inspect.zoom", default),
        help="the wrist plot and its exported figure show these seconds (a long result is unreadable as a whole)",
    )
    wrists = wrist_figure(motions, labels=labels, bands=result.control, thresholds=db.thresholds)
    if zoom[1] > zoom[0]:
        wrists.update_xaxes(range=list(zoom))
    st.plotly_chart(wrists, key="inspect.compare_wrists", config={"displaylogo": False})
    paper_view(motions, labels, wrists, zoom, duration)


def paper_view(motions: list, labels: list[str], wrists: Any, zoom: tuple[float, float], duration: float) -> None:
    """Figures for a paper: a filmstrip of the compared results at chosen times and the wrist plot,
    as PNG, SVG or PDF at print size (made when the download is clicked)."""
    ss = st.session_state
    st.markdown("**Figures for a paper**")
    c = st.columns([3, 1, 1, 1])
    evenly = ", ".join(f"{t:.1f}" for t in np.linspace(zoom[0], zoom[1], 5))
    text = ss["inspect.film_times"] = c[0].text_input(
        "Filmstrip times [s]", key=state.persistent_key("inspect.film_times", evenly), help="commas between them"
    )
    fmt = ss["inspect.fig_format"] = c[1].selectbox(
        "Format", list(FORMATS), key=state.persistent_key("inspect.fig_format", "pdf"), format_func=str.upper
    )
    width = ss["inspect.fig_width"] = c[2].number_input(
        "Width [mm]", min_value=40.0, max_value=500.0, step=5.0, key=state.persistent_key("inspect.fig_width", 170.0)
    )
    dpi = ss["inspect.fig_dpi"] = c[3].number_input(
        "PNG dpi", min_value=72, max_value=1200, step=50, key=state.persistent_key("inspect.fig_dpi", 300)
    )
    with display.user_errors():
        times = gs.parse_times(text, duration=duration)
        film = filmstrip_figure(motions, times, labels=labels)
        st.plotly_chart(film, key="inspect.filmstrip", config={"displaylogo": False})
        d = st.columns(2)
        for col, name, fig, kwargs in (
            (d[0], "filmstrip", film, {}),
            (d[1], "wrists", wrists, {"time_range": zoom if zoom[1] > zoom[0] else None}),
        ):
            col.download_button(
                f"{name.capitalize()} ({fmt.upper()}, {width:g} mm)",
                data=functools.partial(figure_bytes, fig, fmt, width_mm=float(width), dpi=int(dpi), **kwargs),
                file_name=f"{name}.{fmt}",
                mime=FORMATS[fmt],
                key=f"inspect.export_{name}",
                on_click="ignore",
            )


def control_words(mask_rule: str) -> str:
    """What "control met" and "steps relaxed" measure, and why the first can be under 100 % when the second is 0."""
    where = "at a window's first and last frame" if mask_rule == "ends" else "at every frame of a window"
    return (
        "**control met**: of the output frames a control covers, the share whose motion meets it, measured on "
        "the k-NN motion as the database's thresholds define it (for `right_hand=high`: the right wrist above "
        "the high threshold). **steps relaxed**: steps where no database window satisfied the control, so the "
        "search dropped the control for that step and matched on pose and speech alone. "
        f"The search checks a control {where}; frames between them, the joins between steps and speeds "
        "measured across a join may still miss it, so control met can be below 100 % with no step relaxed."
    )


def main() -> None:
    st.title("Retrieval inspector")
    db = sidebar.sidebar_database()
    record = state.current_synthesis(db)
    if record is None:
        st.info("Run a synthesis on the Synthesize page first: this page shows how its search chose every step.")
        nav.link("Synthesize")
        return
    result = record["result"]
    st.caption(
        f"**{display.escape_markdown(result.source)}** · "
        f"{result.search.n_steps} steps of {result.config.segment} frames · "
        f"k = {result.config.k} · candidates in the combined ranking of pose rank + audio rank, best first"
    )
    step = pick_step(db, result)
    step_view(db, record, step)
    pins_view(db, record)
    compare_view(db, record)


main()
