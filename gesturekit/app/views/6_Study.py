"""The researcher's view of a study: its design, who took part, live counts, the analysis, CSV downloads.

Everything comes from the study folder (``design.json``, ``manifest.csv``) and its responses
(the study folder's SQLite, or a PostgreSQL database by URL), read afresh on every run, so the
page shows the study as it stands. The key (which system made which video) is shown here and
only here: when the app is served to others the page asks for the study's researcher password
first (see :func:`served_to_others`).
"""

from __future__ import annotations

import ipaddress
import json
from pathlib import Path

import pandas as pd
import streamlit as st

from gesturekit._io import csv_safe
from gesturekit.app import display, state
from gesturekit.errors import ConfigError
from gesturekit.paths import home
from gesturekit.study.analyse import exclusions, pairwise_table, ratings_table
from gesturekit.study.design import StudyDesign, init_study, load_design, verify_password
from gesturekit.study.report import analyse, boxplot_figure, significance_figure
from gesturekit.study.store import SQLITE_NAME, open_store

#: Bootstrap rounds of the page's analysis: a quick look at every run (``gesturekit study analyse`` for the report).
ROUNDS = 1000

#: Request headers a reverse proxy adds: a request that carries one came from another machine.
FORWARDED_HEADERS = ("forwarded", "x-forwarded-for", "x-real-ip", "x-forwarded-host")


def served_to_others() -> bool:
    """Whether this page may be seen by someone other than the person at the server.

    True when Streamlit listens on an address other than the loopback (unset means every
    interface), or when the request came through a reverse proxy (it carries a forwarding
    header): the two ways of serving the app to others (``docs/guides/app.md``, "Serving the app to others").
    """
    address = str(st.get_option("server.address") or "")
    try:
        local = bool(address) and ipaddress.ip_address(address).is_loopback
    except ValueError:
        local = address == "localhost"
    headers = {k.lower() for k in (st.context.headers or {}).keys()}
    return not local or any(h in headers for h in FORWARDED_HEADERS)


def choose_folder() -> Path | None:
    """The study folder typed by the user (checked against the allowed folders), None while empty."""
    folder = st.session_state["studyrun.folder"] = st.text_input(
        "Study folder",
        key=state.persistent_key("studyrun.folder", str(home() / "study")),
        help="a folder `gesturekit stimuli` wrote and `gesturekit study init` gave a design",
    )
    if not folder.strip():
        st.info("Type the folder of a study.")
        return None
    path = display.allowed(Path(folder.strip()).expanduser(), what="study folder")
    if not path.exists():  # the first visit: nothing is wrong yet, there is simply no study
        st.info(
            "No study in this folder yet. The **Study stimuli** page makes one (its videos, manifest and "
            "presentation order); then give it a design here. Or type the folder of an existing study."
        )
        return None
    if not (path / "manifest.csv").is_file():
        # the folder is in the input above: the message says what is wrong without repeating the path
        raise ConfigError(
            "the study folder typed above is not a study yet (no manifest.csv): "
            "make the stimuli first (Study stimuli page)"
        )
    return path


def design_form(folder: Path, *, replace: bool) -> None:
    """The study's design, made here as ``gesturekit study init`` makes it: the pages, the checks, the
    researcher's password and where participants go when done."""
    with st.form("studyrun.design"):
        left, right = st.columns(2)
        scale = left.radio(
            "Rating scale",
            ["likert7", "slider100"],
            format_func={"likert7": "7 points (the paper's)", "slider100": "0-100 slider (HEMVIP's)"}.get,
        )
        rating = left.checkbox("Rating pages (every animation of a speech on one page)", value=True)
        pairwise = left.checkbox("Pairwise pages (which of two fits the speech better)", value=False)
        attention = right.number_input("Attention checks per participant", min_value=0, max_value=20, value=2)
        audio_check = right.checkbox("Audio check first (count the beeps)", value=True)
        password = right.text_input("Researcher password", type="password")
        redirect = right.text_input("Redirect when done (optional)", placeholder="https://app.prolific.com/...{code}")
        confirm = True
        if replace:
            confirm = st.checkbox("Replace the existing design (its page ids and completion code change)")
        submitted = st.form_submit_button("Write the design")
    if not submitted:
        return
    if not confirm:
        st.warning("Tick 'Replace the existing design' to replace it.")
        return
    bar = st.progress(0.0, text="Making the attention checks")
    init_study(
        folder,
        scale=scale,
        rating=rating,
        pairwise=pairwise,
        attention=int(attention),
        audio_check=audio_check,
        password=password or None,
        redirect=redirect.strip() or None,
        overwrite=replace,
        progress=lambda done, total: bar.progress(done / max(total, 1), text="Making the attention checks"),
    )
    bar.empty()
    st.success("Design written: start the participants' server with `gesturekit study serve STUDY`.")


def unlocked(design: StudyDesign) -> bool:
    """Whether the page may show the study: always on the researcher's own machine; when served,
    only after the design's researcher password is typed (a study without one is not shown)."""
    if not served_to_others():
        return True
    if design.password_hash is None:
        st.error(
            "The app is served to others and this study has no researcher password: set one with "
            "`gesturekit study init STUDY --password P --force` to see its responses here."
        )
        return False
    typed = st.text_input("Researcher password", type="password", key="studyrun.password")
    if not typed:
        st.info("The app is served to others: type the study's researcher password.")
        return False
    if not verify_password(typed, design.password_hash):
        st.error("Wrong password.")
        return False
    return True


def participants(frame: pd.DataFrame) -> None:
    st.subheader("Participants")
    status = frame["status"].value_counts() if len(frame) else pd.Series(dtype=int)
    cols = st.columns(4)
    cols[0].metric("Started", len(frame))
    cols[1].metric("Finished", int(status.get("finished", 0)))
    cols[2].metric("Failed checks", int(status.get("failed_checks", 0)))
    cols[3].metric("Active", int(status.get("active", 0)))
    st.dataframe(
        frame[["row", "prolific_pid", "status", "failed_checks", "started_at", "finished_at"]],
        hide_index=True,
        key="studyrun.participants",
    )


def counts(folder: Path, ratings: pd.DataFrame, pairwise: pd.DataFrame, excluded: set) -> None:
    """Raters per stimulus and per condition (system) so far; excluded participants counted apart."""
    st.subheader("Counts so far")
    manifest = pd.read_csv(folder / "manifest.csv", dtype=str)[["id", "audio", "system"]]
    kept = ratings[~ratings["participant"].isin(excluded)]
    per = kept.groupby(["speech", "system"])["participant"].nunique().rename("raters").reset_index()
    table = manifest.merge(per, how="left", left_on=["audio", "system"], right_on=["speech", "system"])
    table["raters"] = table["raters"].fillna(0).astype(int)
    left, right = st.columns(2)
    left.markdown("**Per stimulus** (participants who rated it, exclusions left out)")
    left.dataframe(table[["id", "audio", "system", "raters"]], hide_index=True, key="studyrun.per_stimulus")
    by_system = table.groupby("system", sort=True)["raters"].sum().rename("ratings").reset_index()
    right.markdown("**Per condition** (ratings of its stimuli)")
    right.dataframe(by_system, hide_index=True, key="studyrun.per_condition")
    if len(pairwise):
        pairs = (
            pairwise[~pairwise["participant"].isin(excluded)]
            .groupby(["system_left", "system_right"])
            .size()
            .rename("answers")
            .reset_index()
        )
        right.markdown("**Pairwise comparisons**")
        right.dataframe(pairs, hide_index=True, key="studyrun.per_pair")


def analysis(ratings: pd.DataFrame, pairwise: pd.DataFrame, excl: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """The analysis so far (exclusions applied); returns its tables to download (none while too small)."""
    st.subheader("Analysis")
    try:
        report = analyse(ratings, pairwise, excl, rounds=ROUNDS)
    except ConfigError as exc:  # too few answers yet: the study's state, not a fault
        st.info(display.escape_markdown(exc.problem))
        return {}
    st.caption(
        f"{report.included} participants analysed (not excluded, at least one rating or pairwise answer), "
        f"{report.excluded} excluded by the checks; bootstrap {ROUNDS} rounds "
        "(`gesturekit study analyse` writes the full report)."
    )
    st.markdown("**Participant flow**\n\n" + "\n".join(f"- {line}" for line in report.flow_lines()))
    for warning in report.warnings:
        st.warning(display.escape_markdown(warning))
    tables = {"flow": report.participants}
    if report.summary is not None:
        st.markdown("**Ratings per system** (participants' means; 95 % bootstrap intervals)")
        st.dataframe(report.summary, hide_index=True, key="studyrun.summary")
        st.plotly_chart(boxplot_figure(report), key="studyrun.boxplots")
        tables["summary"] = report.summary
    if report.tests is not None:
        st.markdown("**Pairwise differences** (Wilcoxon signed-rank, Holm-Bonferroni)")
        st.dataframe(report.tests, hide_index=True, key="studyrun.tests")
        st.plotly_chart(significance_figure(report), key="studyrun.significance")
        tables["tests"] = report.tests
    if report.bradley_terry is not None:
        st.markdown("**Pairwise preferences** (Bradley-Terry, Elo scale)")
        st.dataframe(report.bradley_terry, hide_index=True, key="studyrun.bradley_terry")
        tables["bradley_terry"] = report.bradley_terry
    return tables


def downloads(tables: dict[str, pd.DataFrame]) -> None:
    st.subheader("Downloads")
    cols = display.download_columns(len(tables))
    for col, (name, frame) in zip(cols, tables.items()):
        col.download_button(
            f"{name}.csv",
            data=csv_safe(frame).to_csv(index=False).encode("utf-8"),
            file_name=f"{name}.csv",
            mime="text/csv",
            key=f"studyrun.download_{name}",
            on_click="ignore",
        )


def show(folder: Path) -> None:
    design = load_design(folder)
    if not unlocked(design):
        return
    url = st.text_input(
        "Responses database",
        key="studyrun.store",
        type="password",  # a PostgreSQL URL may hold its password
        placeholder="postgresql://user:password@host/db (empty: the study folder's SQLite file)",
    )
    if not url.strip() and not (folder / SQLITE_NAME).is_file():
        st.info("No participant has started yet: start the participants' server with `gesturekit study serve`.")
        return
    store = open_store(url.strip() or None, folder)
    try:
        people, responses = store.participants_frame(), store.responses_frame()
    finally:
        store.close()
    frames = (responses, people)
    participants(people)
    ratings, pairwise, excl = ratings_table(design, frames), pairwise_table(design, frames), exclusions(design, frames)
    counts(folder, ratings, pairwise, set(excl.loc[excl["excluded"], "participant"]))
    as_text = {c: responses[c].map(json.dumps) for c in ("answers", "events")}  # dicts and lists as JSON cells
    tables = {"participants": people, "responses": responses.assign(**as_text)}
    tables |= {"ratings": ratings, "pairwise": pairwise, "exclusions": excl}
    tables |= analysis(ratings, pairwise, excl)
    downloads(tables)


def main() -> None:
    st.title("Study")
    st.caption(
        "A running study: who started, finished or failed the attention checks, how many ratings each "
        "stimulus and condition has, and the analysis so far. Start the participants' server with "
        "`gesturekit study serve STUDY`."
    )
    with display.user_errors():
        folder = choose_folder()
        if folder is None:
            return
        if not (folder / "design.json").is_file():
            st.subheader("Design")
            st.caption("This stimuli folder has no design yet: choose its pages and checks.")
            design_form(folder, replace=False)
            if not (folder / "design.json").is_file():
                return
        elif not served_to_others():
            with st.expander("Design"):
                design_form(folder, replace=True)
        show(folder)


main()
