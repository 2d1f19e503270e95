"""User-study stimuli: speeches x systems as identical-looking videos, a manifest, a balanced order."""

from __future__ import annotations

import tempfile
from pathlib import Path

import streamlit as st

from gesturekit.app import display, resources, sidebar, state
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.takes import AUDIO_EXTENSIONS
from gesturekit.errors import ConfigError
from gesturekit.evaluate.baselines import SYSTEM_DESCRIPTIONS, SYSTEMS
from gesturekit.options import option_of, widget_limits
from gesturekit.paths import home
from gesturekit.study.stimuli import StudyConfig, make_stimuli, plan_stimuli
from gesturekit.workspace import speech_files

RESULT = "study.result"  # the user's last study: folder, manifest, order (per session)
RESOLUTIONS = ("320x240", "640x480", "1280x720")
PREVIEWS = 3


def _speech_files(folder: str) -> list[Path]:
    if not folder.strip():
        return []
    p = Path(folder.strip()).expanduser()
    display.allowed(p, what="folder of speech files")  # before looking: no listing of other folders
    return speech_files(p)


def _limits(name: str) -> dict:
    """The widget limits of :class:`StudyConfig`'s option ``name``, and how its default is said."""
    return {**widget_limits(StudyConfig, name), "default_help": option_of(StudyConfig, name).default_help}


def _number(col, label: str, name: str, **options):
    """A whole-number input of :class:`StudyConfig`'s option ``name``: its bounds, default and help from the field
    (an empty box: None, the field's default where it is None)."""
    lim = _limits(name)
    key = state.persistent_key(f"study.{name}", lim["default"])
    help_ = lim["help"] + (f" (empty: {lim['default_help']})" if lim["default_help"] else "")
    return col.number_input(
        label, min_value=lim["min"], max_value=lim["max"], step=lim["step"], key=key, help=help_, **options
    )


def settings(db: MatchingDatabase) -> dict:
    """The study's widgets; returns the options of make_stimuli and the speech names."""
    ss, pk = st.session_state, state.persistent_key
    left, right = st.columns(2)
    with left:
        st.markdown("**Speech**")
        folder = ss["study.folder"] = st.text_input(
            "Folder of speech files",
            key=pk("study.folder", ""),
            help=f"every {'/'.join(AUDIO_EXTENSIONS)} file in it, in name order",
        )
        uploads = st.file_uploader(
            "…and/or upload speech files",
            type=[e[1:] for e in AUDIO_EXTENSIONS],
            accept_multiple_files=True,
            key="study.uploads",
        )
        holdouts = ss["study.holdouts"] = st.text_input(
            "Held-out parts of the database (needed for gt)",
            key=pk("study.holdouts", ""),
            placeholder="TAKE:START-END, TAKE:START-END",
            help=_limits("holdouts")["help"],
        )
    with right:
        st.markdown("**Systems and design**")
        systems = ss["study.systems"] = st.multiselect(
            "Systems",
            list(SYSTEMS),
            key=pk("study.systems", list(_limits("systems")["start"])),
            # short names on the chips so several fit a laptop's column; what each is, in the help and below
            help=_limits("systems")["help"]
            + "\n\n"
            + "\n".join(f"- **{s}**: {SYSTEM_DESCRIPTIONS[s]}" for s in SYSTEMS),
        )
        if systems:
            st.caption(" · ".join(f"**{s}**: {SYSTEM_DESCRIPTIONS[s]}" for s in systems))
        c = st.columns(3)
        seed = ss["study.seed"] = _number(c[0], "Seed", "seed")
        participants = ss["study.participants"] = _number(c[1], "Participants", "participants", placeholder="auto")
        resolution = ss["study.resolution"] = c[2].selectbox(
            "Resolution",
            RESOLUTIONS,
            key=pk("study.resolution", "x".join(map(str, _limits("resolution")["default"]))),
            help=_limits("resolution")["help"],
        )
        control = ss["study.control"] = st.text_input(
            "Control track (optional)",
            key=pk("study.control", _limits("control")["default"]),
            placeholder="0-3:left_hand=high",
            help=_limits("control")["help"],
        )
        refiner = ""
        if "knn+cgan" in systems:
            # the refiner Synthesize applies by default (one trained on this database, or the shipped one)
            refiner = ss["study.refiner"] = st.text_input(
                "Refiner folder (for knn+cgan)",
                key=pk("study.refiner", resources.default_refiner(db)),
                help=_limits("refiner")["help"],
            )
        c = st.columns([2, 1])  # "Parallel renders" on one line at 1280 px
        out = ss["study.out"] = c[0].text_input("Study folder to write", key=pk("study.out", str(home() / "study")))
        workers = ss["study.workers"] = _number(
            c[1], "Parallel renders", "workers", placeholder="all"
        )  # "all cores" did not fit beside the steppers; the help says "(empty: all cores)"
        overwrite = st.checkbox(
            "replace an existing study there",
            key="study.overwrite",
            help="replaces only a study gesturekit made; any other folder is kept",
        )
    names = [f.name for f in _speech_files(folder)] + [u.name for u in uploads or []]
    holdout_list = [h.strip() for h in holdouts.split(",") if h.strip()]
    return {
        "folder": folder,
        "uploads": uploads or [],
        "holdouts": holdout_list,
        "systems": systems,
        "seed": seed,
        "participants": participants,
        "resolution": tuple(int(v) for v in resolution.split("x")),
        "control": control.strip(),
        "refiner": refiner.strip() or None,
        "refiner_checked": _refiner_checked(db, systems, refiner.strip()),
        "out": out.strip(),
        "workers": workers,
        "overwrite": overwrite,
        "names": names + holdout_list,
    }


def _refiner_checked(db: MatchingDatabase, systems: list, refiner: str) -> bool:
    """Whether the refiner knn+cgan needs is there and fits ``db`` (said on the page when not)."""
    if "knn+cgan" not in systems:
        return True
    if not refiner:
        st.error(
            "knn+cgan needs a refiner: type the folder of one trained on this database in "
            "**Refiner folder**, or leave knn+cgan out of the systems."
        )
        return False
    with display.user_errors():  # config and layout only (no torch); the weights load with the work
        resources.check_refiner(refiner, db)
        return True
    return False


def conditions(opts: dict) -> bool:
    """The table of conditions the study will have; False when it has none yet or a choice is wrong."""
    if not opts["names"] or not opts["systems"]:
        st.info("Choose speech (a folder, uploads or held-out parts) and at least one system.")
        return False
    if not opts["refiner_checked"]:
        return False
    plan = plan_stimuli(
        opts["names"], opts["systems"], seed=opts["seed"], participants=opts["participants"], controls=opts["control"]
    )
    st.subheader("Conditions")
    st.caption(
        f"{len(opts['names'])} speeches × {len(opts['systems'])} systems = {len(plan.conditions)} stimuli, "
        f"ordered for {plan.order['participant'].nunique()} participants. The ids are the file names; "
        "this table is the key and stays with the experimenter."
    )
    st.dataframe(plan.conditions, hide_index=True, key="study.conditions")
    return True


def run(db: MatchingDatabase, opts: dict) -> None:
    if not opts["out"]:
        raise ConfigError("type the study folder to write")
    display.allowed(opts["out"], what="study folder to write", write=True)
    if opts["refiner"] not in (None, "demo"):  # "demo": the shipped refiner, by name
        display.allowed(opts["refiner"], what="refiner folder")
    bar = st.progress(0.0, text="synthesising…")

    def progress(stage, done, total):
        # synthesis is quick; rendering takes most of the time
        frac = 0.1 * done / total if stage == "synthesis" else 0.1 + 0.9 * done / total
        bar.progress(min(1.0, frac), text=f"{stage}: {done}/{total}")

    with tempfile.TemporaryDirectory(prefix="gesturekit-study-") as tmp:
        files = _speech_files(opts["folder"])
        for up in opts["uploads"]:
            target = Path(tmp) / Path(up.name).name
            target.write_bytes(up.getvalue())
            files.append(target)
        config = StudyConfig(
            audio=tuple(files),
            holdouts=tuple(opts["holdouts"]),
            systems=tuple(opts["systems"]),
            seed=opts["seed"],
            participants=opts["participants"],
            control=opts["control"],
            refiner=opts["refiner"],
            resolution=opts["resolution"],
            workers=opts["workers"],
        )
        res = make_stimuli(db, config, out=opts["out"], overwrite=opts["overwrite"], progress=progress)
    bar.progress(1.0, text=f"{len(res.videos)} stimuli written")
    st.session_state[RESULT] = {"folder": str(res.folder), "manifest": res.manifest, "order": res.order}


def show_result() -> None:
    result = st.session_state.get(RESULT)
    if result is None:
        return
    folder = Path(result["folder"])
    st.subheader("Study")
    st.success(
        f"Videos in {display.escape_markdown(folder / 'videos')}; "
        f"manifest (the key) {display.escape_markdown(folder / 'manifest.csv')}; "
        f"presentation order {display.escape_markdown(folder / 'order.csv')}."
    )
    first = result["order"][result["order"]["participant"] == 1]["id"].tolist()[:PREVIEWS]
    st.markdown(f"**Preview**: the first {len(first)} stimuli participant 1 sees, as they will see them")
    cols = st.columns(max(len(first), 1))
    for col, sid in zip(cols, first):
        path = folder / "videos" / f"{sid}.mp4"
        col.video(path.read_bytes(), format="video/mp4")
        col.caption(display.escape_markdown(sid))
    with st.expander("Manifest and presentation order"):
        st.dataframe(result["manifest"], hide_index=True, key="study.manifest")
        st.dataframe(result["order"], hide_index=True, key="study.order")


def main() -> None:
    st.title("Study stimuli")
    st.caption(
        "Every speech rendered with every system in one look (fixed camera, same size and frame rate, "
        "speech at one loudness), named by opaque ids, with a balanced presentation order per participant."
    )
    db = sidebar.sidebar_database()
    opts = settings(db)
    ready = conditions(opts)
    if ready and st.button("Make the stimuli", type="primary", key="study.go"):
        with display.user_errors():
            run(db, opts)
    show_result()


main()
