"""The analysed N and the participant flow (CONSORT style) of a study run through its store.

14 participants answer the real study (2 of them fail the attention checks and are stopped), two more only
open the entry link, one stops after the audio check (no kept answer) and one drops out after two rating
pages. Every analysed table has the same N as the report's "analysed", and the flow counts each participant
once: started = answered nothing + excluded + no kept answer + analysed.
"""

from __future__ import annotations

import pandas as pd
import pytest

from gesturekit.study import analyse as A
from gesturekit.study.design import init_study
from gesturekit.study.report import analyse, write_report
from gesturekit.study.store import open_store
from tests.study_helpers import study_folder, take_part, tiny_study  # noqa: F401 (fixtures)

pytestmark = pytest.mark.slow  # tiny_study makes a stimuli folder once per session


@pytest.fixture
def crowd(study_folder):  # noqa: F811
    design = init_study(study_folder, attention=2)
    store = open_store(None, study_folder)
    attentive = [take_part(store, design, pid=f"A{i}") for i in range(12)]
    careless = [take_part(store, design, attentive=False, pid=f"C{i}") for i in range(2)]
    idle = [store.start(design.participants, prolific_pid=f"I{i}")[0].token for i in range(2)]
    audio_only = take_part(store, design, pages=2, pid="B0")  # instructions, the audio check
    dropout = take_part(store, design, pages=4, pid="D0")  # ... and two rating pages
    frames = (store.responses_frame(), store.participants_frame())
    store.close()
    return design, frames, dict(attentive=attentive, careless=careless, idle=idle, audio=audio_only, drop=dropout)


def test_the_analysed_n_counts_only_who_has_a_kept_answer(crowd, tmp_path):
    design, frames, who = crowd
    report = analyse(
        A.ratings_table(design, frames), A.pairwise_table(design, frames), A.exclusions(design, frames), rounds=50
    )
    # the 12 attentive and the one who dropped out after two rating pages
    assert report.included == 13
    assert set(report.summary["n"]) == {13}
    assert set(report.tests["n"]) == {13}
    flow = report.flow
    assert flow["started"] == 18
    assert flow["answered_nothing"] == 2
    assert flow["excluded"] == 2 and flow["excluded_reasons"] == {"failed more attention checks than allowed": 2}
    assert flow["no_kept_answer"] == 1
    assert flow["analysed"] == 13 and flow["analysed_finished"] == 12
    assert flow["dropped_out"] == {4: 1}  # the analysed who stopped, by the last page they answered
    assert flow["started"] == flow["answered_nothing"] + flow["excluded"] + flow["no_kept_answer"] + flow["analysed"]

    table = report.participants.set_index("participant")
    assert table.loc[who["attentive"], "analysed"].all() and table.loc[who["drop"], "analysed"]
    assert not table.loc[who["idle"] + who["careless"] + [who["audio"]], "analysed"].any()
    assert (table.loc[who["idle"], "outcome"] == "answered nothing").all()
    assert table.loc[who["drop"], "outcome"].startswith("analysed; dropped out after page 4 of ")
    assert table.loc[who["audio"], "outcome"].startswith("no rating or pairwise answer; dropped out after page 2")
    assert table.loc[who["careless"][0], "outcome"].startswith("excluded: failed more attention checks")

    files = write_report(report, tmp_path / "analysis")
    assert tmp_path / "analysis" / "participants.csv" in files
    csv = pd.read_csv(tmp_path / "analysis" / "participants.csv")
    assert int(csv["analysed"].sum()) == 13 and len(csv) == 18
    md = (tmp_path / "analysis" / "report.md").read_text()
    for line in (
        "Started: 18",
        "Answered nothing: 2",
        "Excluded: 2 (failed more attention checks than allowed: 2)",
        "No rating or pairwise answer: 1",
        "Analysed: 13 (finished: 12; dropped out after page 4: 1)",
    ):
        assert line in md, line
    assert "analysed: 14" not in md.lower()
    html = (tmp_path / "analysis" / "report.html").read_text()
    assert "Analysed: 13" in html


def test_the_instructions_count_the_videos_a_page_shows(crowd):
    design, _, _ = crowd
    # 3 systems, and an attention check video on some rating pages: 3 or 4 videos
    assert "you will see 3 or 4 different animations" in design.instructions


def test_the_command_prints_the_flow(crowd, capsys):
    from gesturekit.cli import main

    design, _, _ = crowd
    assert main(["study", "analyse", str(design.folder), "--rounds", "20"]) == 0
    out = capsys.readouterr().out
    assert "18 started, 2 answered nothing, 2 excluded by the checks, 1 with no rating or pairwise answer, " in out
    assert "13 analysed (12 finished)" in out
