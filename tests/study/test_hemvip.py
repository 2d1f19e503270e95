"""HEMVIP interop: configs per participant, and HEMVIP results read back as the same responses."""

import dataclasses
import json
import shutil

import numpy as np
import pandas as pd
import pytest

from gesturekit.cli import main
from gesturekit.errors import InputFileError, OutputError
from gesturekit.study import init_study, media_index, participant_pages
from gesturekit.study.hemvip import RESPONSE_COLUMNS, export_hemvip, import_hemvip
from tests.study_helpers import STUDY_SYSTEMS, tiny_study  # noqa: F401

pytestmark = pytest.mark.slow  # tiny_study builds a demo database and makes a stimuli folder once per module


@pytest.fixture(scope="module")
def design(tiny_study, tmp_path_factory):  # noqa: F811
    folder = tmp_path_factory.mktemp("hemvip") / "study"
    shutil.copytree(tiny_study, folder)
    return init_study(folder, pairwise=True)


@pytest.mark.slow
def test_export_writes_a_config_per_participant(design, tmp_path):
    vimeo = {mid: str(700000 + i) for i, mid in enumerate(sorted(media_index(design)))}
    files = export_hemvip(design, tmp_path / "configs", vimeo=vimeo)
    assert [f.name for f in files] == [f"participant_{r:04d}.json" for r in range(1, design.participants + 1)]
    index = media_index(design)
    for row, f in enumerate(files, start=1):
        text = f.read_text()
        config = json.loads(text)
        pages = participant_pages(design, row)
        kinds = [p["type"] for p in config["pages"]]
        n_rating = sum(p.kind == "rating" for p in pages)
        assert kinds[0] == "generic" and kinds[-1] == "finish"
        assert kinds.count("video") == n_rating * len(design.prompts)
        assert kinds.count("videopc") == sum(p.kind == "pairwise" for p in pages)
        for page in config["pages"]:
            for cond, url in page.get("stimuli", []):
                assert url == f"https://player.vimeo.com/video/{vimeo[cond]}" and cond in index
        assert [q["name"] for q in config["pages"][-1]["questionnaire"]] == ["age", "comments"]
        # nothing names a system or a speech
        assert not any(s in text for s in STUDY_SYSTEMS) and ".wav" not in text
    with pytest.raises(OutputError, match="exists"):
        export_hemvip(design, tmp_path / "configs", vimeo=vimeo)


def _simulate(design, row, rng, token):
    """A participant's answers (as the server would store them) and the HEMVIP session that gives them."""
    config_pages = {p.id: p for p in participant_pages(design, row)}
    truth, trials = [], []
    for page in config_pages.values():
        ms = int(rng.integers(2000, 60000))
        if page.kind == "rating":
            answers = {m.id: {p: int(rng.integers(1, 8)) for p, _ in design.prompts} for m in page.media}
            ms = 0  # a page per prompt in HEMVIP: the page's time is theirs together
            for prompt, _ in design.prompts:
                t = int(rng.integers(2000, 60000))
                ms += t
                responses = [
                    {"stimulus": mid, "score": str(round((a[prompt] - 1) * 100 / 6)), "time": t}
                    for mid, a in answers.items()
                ]
                trials.append({"type": "video", "id": f"{page.id}-{prompt}", "responses": responses})
        elif page.kind == "pairwise":
            choice = int(rng.integers(-1, 2))
            left, right = page.media
            responses = [
                {"stimulus": left.id, "score": choice == -1, "time": ms},
                {"stimulus": right.id, "score": choice == 1, "time": ms},
            ]
            answers = {"choice": choice}
            trials.append({"type": "videopc", "id": page.id, "responses": responses})
        elif page.kind == "questionnaire":
            answers = {"age": int(rng.integers(18, 80)), "comments": "fine"}
            ms = 0
        else:
            continue
        truth.append(
            {
                "token": token,
                "row": row,
                "page_id": page.id,
                "page_index": page.index,
                "kind": page.kind,
                "answers": answers,
                "elapsed_s": ms / 1000,
                "submitted_at": None,
            }
        )
    age = next(t["answers"]["age"] for t in truth if t["kind"] == "questionnaire")
    rng.shuffle(trials)  # HEMVIP may randomise the page order; the ids say where each belongs
    session = {
        "testId": "study",
        "userId": token,
        "trials": trials,
        "participant": {"name": ["age", "comments"], "response": [str(age), "fine"]},
    }
    return truth, session


def test_hemvip_results_import_as_the_same_responses(design, tmp_path):
    rng = np.random.default_rng(0)
    truth, sessions = [], []
    for row, token in [(1, "PID1"), (2, "PID2"), (5, "PID5")]:
        t, s = _simulate(design, row, rng, token)
        truth += t
        sessions.append(s)
    (tmp_path / "export.json").write_text(json.dumps(sessions[:2]))  # HEMVIP's export: a list
    (tmp_path / "one.json").write_text(json.dumps(sessions[2]))  # or one session
    got = import_hemvip(design, [tmp_path / "export.json", tmp_path / "one.json"])
    want = pd.DataFrame(truth, columns=RESPONSE_COLUMNS).sort_values(["token", "page_index"]).reset_index(drop=True)
    assert list(got.columns) == RESPONSE_COLUMNS
    pd.testing.assert_frame_equal(got, want, check_dtype=False)
    # on a 0..100 design the scores are kept as they are
    slider = dataclasses.replace(design, scale="slider100")
    got = import_hemvip(slider, [tmp_path / "one.json"])
    first = got[got["kind"] == "rating"].iloc[0]
    page = next(s for s in sessions[2]["trials"] if s["id"].startswith(first["page_id"] + "-"))
    prompt = page["id"].split("-")[1]
    assert {r["stimulus"]: int(r["score"]) for r in page["responses"]} == {
        m: a[prompt] for m, a in first["answers"].items()
    }


def test_import_refuses_what_is_not_this_study(design, tmp_path):
    rng = np.random.default_rng(1)
    _, session = _simulate(design, 1, rng, "PID")
    bad = dict(session, trials=session["trials"] + [{"type": "video", "id": "ffffffffffff-sync", "responses": []}])
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(InputFileError, match="bad.json: session 0: the page 'ffffffffffff-sync'"):
        import_hemvip(design, [tmp_path / "bad.json"])
    _, other = _simulate(design, 2, rng, "PID")
    mixed = dict(session, trials=session["trials"] + other["trials"])
    (tmp_path / "mixed.json").write_text(json.dumps(mixed))
    with pytest.raises(InputFileError, match="several participants"):
        import_hemvip(design, [tmp_path / "mixed.json"])
    (tmp_path / "junk.json").write_text("{")
    with pytest.raises(InputFileError, match="not a HEMVIP result"):
        import_hemvip(design, [tmp_path / "junk.json"])


def test_hemvip_commands(design, tmp_path, capsys):
    vimeo = tmp_path / "vimeo.csv"
    vimeo.write_text("id,vimeo\n" + "".join(f"{m},{700000 + i}\n" for i, m in enumerate(sorted(media_index(design)))))
    cfg = str(tmp_path / "cfg")
    assert main(["study", "export-hemvip", str(design.folder), "--out", cfg, "--vimeo", str(vimeo)]) == 0
    assert len(list((tmp_path / "cfg").glob("participant_*.json"))) == design.participants
    _, session = _simulate(design, 3, np.random.default_rng(2), "PID3")
    (tmp_path / "r.json").write_text(json.dumps([session]))
    out = tmp_path / "responses.csv"
    assert main(["study", "import-hemvip", str(design.folder), str(tmp_path / "r.json"), "--out", str(out)]) == 0
    table = pd.read_csv(out)
    assert set(table["kind"]) == {"rating", "pairwise", "questionnaire"} and set(table["row"]) == {3}
    assert all(isinstance(json.loads(a), dict) for a in table["answers"])
    assert main(["study", "import-hemvip", str(design.folder), str(tmp_path / "r.json"), "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
