"""The Retrieval inspector page, run headless with Streamlit's AppTest: candidates per step, pins, k comparison."""

from __future__ import annotations

import io
import shutil

import numpy as np
import pytest
import soundfile as sf
from streamlit.testing.v1 import AppTest

from gesturekit import interactive as gs
from gesturekit.app import HOME
from gesturekit.character import look
from gesturekit.database import MatchingDatabase
from gesturekit.datasets.synthetic import generate_demo_take
from tests.conftest import chart_spec as chart
from tests.conftest import plotly_array as array
from tests.conftest import shown, viewer
from tests.waits import APP_RUN_S

pytestmark = pytest.mark.slow  # each module builds its demo database (demo_home) and runs pages in AppTest

SYNTH, INSPECT = "views/1_Synthesize.py", "views/2_Retrieval_inspector.py"
TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)
TOPK = 5


@pytest.fixture(scope="module")
def db(demo_home) -> MatchingDatabase:
    return MatchingDatabase.load(demo_home / "db" / "demo")


def speech_wav(seconds: float = 4.0) -> bytes:
    take, _ = generate_demo_take(seconds=seconds, seed=778, name="speech")
    buf = io.BytesIO()
    sf.write(buf, take.audio, 16000, format="WAV")
    return buf.getvalue()


def synthesized() -> AppTest:
    """A session that uploaded speech, set a control segment and ran with TOPK candidates, now on the inspector."""
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.switch_page(SYNTH).run()
    at.file_uploader(key="synth.upload").set_value(("talk.wav", speech_wav(), "audio/wav")).run()
    at.session_state["synth.segments_editor"] = {
        "edited_rows": {},
        "deleted_rows": [],
        "added_rows": [{"start_s": 1.0, "end_s": 3.0, "constraint": "right_hand=high"}],
    }
    at.number_input(key="_w.synth.record").set_value(TOPK).run()
    at.button(key="synth.go").click().run()
    at.switch_page(INSPECT).run()
    assert not at.exception and not [shown(e.value) for e in at.error], at.exception
    return at


def result(at: AppTest):
    return at.session_state["gk.synthesis"]["result"]


def table(at: AppTest, column: str):
    """The dataframe on the page that has ``column``."""
    return next(d.value for d in at.dataframe if column in d.value.columns)


def motions_in(spec: dict) -> list[int]:
    return sorted({t["meta"]["motion"] for t in spec["data"]})


def set_step(at: AppTest, step: int) -> AppTest:
    at.number_input(key="_w.inspect.step").set_value(step).run()
    assert not at.exception
    return at


def test_without_a_result_the_page_says_where_to_start(app_env):
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.switch_page(INSPECT).run()
    assert not at.exception
    assert any("Synthesize page first" in shown(i.value) for i in at.info)
    assert [p.proto.label for p in at.get("page_link")] == ["Synthesize"]


def test_every_step_lists_its_k_candidates_with_their_sources(app_env, db):
    at = synthesized()
    res = result(at)
    s = res.search
    assert len(table(at, "relaxed")) == s.n_steps
    for step in (0, 3, s.n_steps - 1):
        at = set_step(at, step)
        cands = table(at, "audio_dist")
        assert len(cands) == TOPK
        assert list(cands["clip"]) == list(s.cand_clip[step]) and list(cands["start"]) == list(s.cand_start[step])
        assert list(cands["take"]) == [db.take_names[int(db.clip_take[c])] for c in cands["clip"]]
        np.testing.assert_allclose(cands["pose_dist"], s.cand_pose_dist[step])
        assert cands["chosen"].tolist().index(True) == s.position[step]
        # the chosen window alone in 3D, framed as a presenter, in the chosen one's colours; one point per candidate
        views = viewer(at, "inspect.views")
        step_frames = min((step + 1) * res.config.segment, res.n_frames) - step * res.config.segment
        assert len(views["motions"]) == 1 and len(views["times"]) == step_frames
        assert views["title"] == f"#{int(s.position[step])} · chosen"
        assert views["motions"][0]["scheme"] == look.role_scheme("chosen")
        window = gs.candidate_motion(db, int(s.clip[step]), int(s.start[step]), step_frames)
        shown_joints = window.presence.drawn
        np.testing.assert_allclose(
            views["motions"][0]["points"][:, shown_joints], window.positions[:, shown_joints], atol=2e-3
        )
        (points,) = [t for t in chart(at, "inspect.candidates_plot")["data"] if t["meta"]["part"] == "candidates"]
        np.testing.assert_allclose(array(points["x"]), s.cand_pose_dist[step])
    assert any(m.value.startswith(f"**Step {s.n_steps - 1}**") for m in at.markdown)
    # the candidate's own speech, and that with a second of its take around it; this step's plays in the 3D view
    assert len(at.get("audio")) == 2
    step_speech = gs.step_speech(res, s.n_steps - 1)
    np.testing.assert_allclose(views["audio"][: len(step_speech)], step_speech, atol=1e-4)


def test_a_candidates_speech_comes_with_its_context_marked(app_env, db):
    at = set_step(synthesized(), 3)
    res = result(at)
    row = table(at, "audio_dist").iloc[0]
    n = res.config.segment
    (caption,) = [shown(c.value) for c in at.caption if "the window is" in shown(c.value)]
    spec = chart(at, "inspect.context")
    (band,) = [sh for sh in spec["layout"]["shapes"] if sh["type"] == "rect"]
    take = db.take_audio(int(db.clip_take[row["clip"]]))
    f0 = int(db.clip_start[row["clip"]]) + int(row["start"])
    s0 = round(f0 * 16000 / db.fps)
    before = min(1.0, s0 / 16000)  # a second, or less at the take's start
    assert band["x0"] == pytest.approx(before, abs=1e-6)
    assert band["x1"] - band["x0"] == pytest.approx(n / db.fps, abs=1e-3)
    assert f"the window is {before:.2f}–{before + n / db.fps:.2f} s" in caption
    assert f"{row['take']} at {s0 / 16000:.2f}" in caption
    excerpt, a, b, t0 = __import__("gesturekit.interactive", fromlist=["x"]).segment_in_context(
        db, int(row["clip"]), int(row["start"]), n
    )
    np.testing.assert_array_equal(excerpt, take[round(t0 * 16000) : round(t0 * 16000) + len(excerpt)])
    assert (a, b) == (pytest.approx(before), pytest.approx(band["x1"]))


def test_every_table_names_its_columns_in_words_and_control_met_in_whole_percent(app_env):
    import json

    at = synthesized()
    at.button(key="inspect.compare_go").click().run()
    assert not at.exception
    assert len(at.dataframe) == 3
    for frame in at.dataframe:
        config = json.loads(frame.proto.columns)
        for column in frame.value.columns:
            label = config.get(column, {}).get("label")
            assert label and "_" not in label, (column, label)
    compared = table(at, "control_met")
    met = compared["control_met"].dropna()
    assert len(met) == 3 and ((met == met.round()) & (met >= 0) & (met <= 100)).all()
    frame = next(f for f in at.dataframe if "control_met" in f.value.columns)
    assert json.loads(frame.proto.columns)["control_met"]["type_config"]["format"] == "%d%%"


def test_pinning_a_candidate_changes_that_step_and_can_be_undone(app_env):
    at = set_step(synthesized(), 2)
    before = result(at)
    row = table(at, "audio_dist").iloc[3]
    assert not row["chosen"]
    at.selectbox(key="_w.inspect.candidate").set_value(3).run()
    at.button(key="inspect.use").click().run()
    assert not at.exception and not [shown(e.value) for e in at.error]
    after = result(at)
    assert (
        (after.search.clip[2], after.search.start[2])
        == (row["clip"], row["start"])
        != (before.search.clip[2], before.search.start[2])
    )
    assert after.search.pinned.tolist() == [i == 2 for i in range(after.search.n_steps)]
    np.testing.assert_array_equal(after.search.clip[:2], before.search.clip[:2])  # earlier steps unchanged
    assert table(at, "audio_dist")["chosen"].tolist()[3] or after.search.position[2] == -1
    assert any("**pinned**" in m.value for m in at.markdown)
    assert any(m.value.startswith("step **2**: clip") for m in at.markdown)

    # the pin is kept by the Synthesize page's next run
    at.switch_page(SYNTH).run()
    assert any("Pinned choices" in c.value and f"2: {row['clip']}, {row['start']}" in c.value for c in at.caption)
    at.switch_page(INSPECT).run()
    at.button(key="inspect.unpin_2").click().run()
    assert not at.exception
    undone = result(at)
    assert undone.config.pins == {} and undone.search.equals(before.search)


def test_comparing_k_shows_the_results_side_by_side(app_env):
    at = synthesized()
    at.button(key="inspect.compare_go").click().run()
    assert not at.exception and not [shown(e.value) for e in at.error]
    views = viewer(at, "inspect.compare_views")
    assert [m["label"] for m in views["motions"]] == ["k = 0", "k = 1", "k = 2"]
    compared = table(at, "control_met")
    assert list(compared["k"]) == [0, 1, 2]
    runs = at.session_state["inspect.compare"]["results"]
    assert runs[0].search.equals(result(at).search)
    assert not np.array_equal(runs[0].search.clip, runs[2].search.clip)
    wrists = chart(at, "inspect.compare_wrists")
    assert motions_in(wrists) == [0, 1, 2]


def test_a_result_of_another_database_is_not_inspected_against_this_one(app_env, tmp_path):
    at = synthesized()
    shutil.copytree(app_env / "db" / "demo", tmp_path / "db" / "copy")
    at.run()
    at.sidebar.selectbox[0].select_index(1).run()
    assert not at.exception
    assert any("Synthesize page first" in shown(i.value) for i in at.info)
    assert not at.get("plotly_chart")


def _large(at: AppTest) -> int:
    """The candidate the large view shows (its traces say which)."""
    return {t["meta"]["candidate"] for t in chart(at, "inspect.candidate_large")["data"]}.pop()


def test_table_scatter_and_strip_select_the_candidate_shown_large(app_env, db):
    at = set_step(synthesized(), 3)
    res = result(at)
    s = res.search
    chosen = int(s.position[3])
    assert _large(at) == chosen  # a new step shows its chosen candidate
    strip = chart(at, "inspect.strip")
    assert {t["meta"]["candidate"] for t in strip["data"]} == set(range(TOPK))
    assert sum(t["meta"]["part"] == "ghost" for t in strip["data"]) == TOPK
    others = [p for p in range(TOPK) if p != chosen]

    at.session_state["inspect.candidates"] = {"selection": {"rows": [others[0]], "columns": []}}
    at.run()
    assert _large(at) == others[0] and at.selectbox(key="_w.inspect.candidate").value == others[0]
    (ring,) = [t for t in chart(at, "inspect.candidates_plot")["data"] if t["meta"]["part"] == "selected"]
    assert array(ring["x"])[0] == pytest.approx(s.cand_pose_dist[3][others[0]])

    clip, start = int(s.cand_clip[3][others[1]]), int(s.cand_start[3][others[1]])
    at.session_state["inspect.candidates_plot"] = {
        "selection": {"points": [{"customdata": [clip, start, 0, 0, 0]}], "point_indices": [], "box": [], "lasso": []}
    }
    at.run()
    assert _large(at) == others[1]

    at.session_state["inspect.strip"] = {
        # as the browser sends it: a typed array's values keyed "0", "1", ...
        "selection": {"points": [{"customdata": {"0": others[2]}}], "point_indices": [], "box": [], "lasso": []}
    }
    at.run()
    assert _large(at) == others[2] and at.selectbox(key="_w.inspect.candidate").value == others[2]
    # the 3D view shows the selected one, one at a time, in the colour of its rank
    views = viewer(at, "inspect.views")
    assert views["title"] == f"#{others[2]} · selected" and len(views["motions"]) == 1
    assert views["motions"][0]["scheme"] == look.rank_scheme(others[2])
    # the selectbox selects too, and the two distances are said in words
    at.selectbox(key="_w.inspect.candidate").set_value(others[0]).run()
    assert _large(at) == others[0]
    assert any(m.value.startswith(f"**Why this clip?** Candidate **#{others[0]}**") for m in at.markdown)
    # another step starts again from its chosen candidate
    at = set_step(at, 4)
    assert _large(at) == int(s.position[4])


def test_control_met_and_steps_relaxed_are_explained_in_words(app_env):
    at = synthesized()
    at.button(key="inspect.compare_go").click().run()
    words = " ".join(m.value for m in at.markdown)
    assert "**control met**: of the output frames a control covers" in words
    assert "**steps relaxed**: steps where no database window satisfied the control" in words
    assert "first and last frame" in words  # the rule the search used


def test_figures_for_a_paper_are_offered_at_print_size_over_a_chosen_range(app_env):
    at = synthesized()
    at.button(key="inspect.compare_go").click().run()
    at.slider(key="_w.inspect.zoom").set_value((1.0, 3.0)).run()
    assert not at.exception
    # the page's wrist plot shows the range; the filmstrip's times default to it, evenly
    assert chart(at, "inspect.compare_wrists")["layout"]["xaxis"]["range"] == [1.0, 3.0]
    assert at.text_input(key="_w.inspect.film_times").value == "0.0, 1.0, 2.0, 3.0, 4.0"  # the default's range
    at.text_input(key="_w.inspect.film_times").set_value("0.5, 1.5, 2.5").run()
    film = chart(at, "inspect.filmstrip")
    poses = [t["meta"] for t in film["data"] if t["meta"]["part"] == "pose"]
    assert sorted({m["time"] for m in poses}) == [0.5, 1.5, 2.5] and {m["motion"] for m in poses} == {0, 1, 2}
    names = [b.proto.label for b in at.get("download_button")]
    assert "Filmstrip (PDF, 170 mm)" in names and "Wrists (PDF, 170 mm)" in names
    # a time outside the result is a message, not a traceback
    at.text_input(key="_w.inspect.film_times").set_value("0.5, 999").run()
    assert not at.exception
    assert any("lies outside the result" in shown(e.value) for e in at.error)
