"""HEMVIP interop against what stock HEMVIP (jonepatr/hemvip, branch genea2022) builds and reads, and the
import under hostile files.

HEMVIP's files read for this (the structure, not their code): ``lib/webmushra/video/VideoVisualizer.js``
and ``VideoPCVisualizer.js`` (every video is a ``Vimeo.Player`` built from the stimulus URL),
``lib/webmushra/pages/VideoPage.js`` (``store``: one trial per page, a response ``{stimulus, score, time}``
per video, the score the slider's value as text; ``checkNumConditions``: more than 8 videos stop the
page), ``lib/webmushra/pages/VideoPC.js`` (a response per video, score true/false, both false for
"equal"), ``lib/webmushra/business/PageManager.js`` (``reportBroken``: every score of a videopc page set
to 99), ``lib/webmushra/pages/FinishPage.js`` (``optional: true`` questionnaire items; the browser goes
to the text ``/save`` returns), ``main.py`` (``/save`` returns the ``codes`` collection's ``code`` of the
test id; configs are ``configs/<test id>/*.json``), ``tools/export_data.py`` (a JSON array) and
MongoDB's ``mongoexport`` (one document per line, ``{"$oid": ..}`` ids).
"""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pandas as pd
import pytest

from gesturekit.cli import main
from gesturekit.errors import ConfigError, InputFileError
from gesturekit.study import init_study
from gesturekit.study.analyse import broken_videos, exclusions, pairwise_table, read_responses_csv
from gesturekit.study.hemvip import export_hemvip, import_hemvip, read_vimeo_map
from gesturekit.study.report import analyse
from gesturekit.study.simulate import simulate_study
from tests.study.test_hemvip import _simulate
from tests.study_helpers import tiny_study  # noqa: F401

pytestmark = pytest.mark.slow  # tiny_study builds a demo database and makes a stimuli folder once per session


@pytest.fixture(scope="module")
def design(tiny_study, tmp_path_factory):  # noqa: F811
    folder = tmp_path_factory.mktemp("hemvip2") / "study"
    shutil.copytree(tiny_study, folder)
    return init_study(folder, pairwise=True, redirect="https://app.prolific.com/submissions/complete?cc={code}")


def _vimeo(design):
    from gesturekit.study import media_index

    return {mid: str(500000000 + i) for i, mid in enumerate(sorted(media_index(design)))}


def _session_from_config(config, user, rng):
    """The session HEMVIP's pages store for a config (VideoPage/VideoPC ``store``), answered at random."""
    trials = []
    for page in config["pages"]:
        t = int(rng.integers(1000, 9000))
        if page["type"] == "video":
            responses = [
                {"stimulus": s[0], "score": str(int(rng.integers(0, 101))), "time": t} for s in page["stimuli"]
            ]
        elif page["type"] == "videopc":
            pick = int(rng.integers(0, 3))
            responses = [{"stimulus": s[0], "score": pick == i, "time": t} for i, s in enumerate(page["stimuli"])]
        else:
            continue
        trials.append({"type": page["type"], "id": page["id"], "responses": responses, "interaction": {}})
    names = [q["name"] for q in config["pages"][-1]["questionnaire"]]
    return {
        "testId": "study",
        "userId": user,
        "trials": trials,
        "participant": {"name": names, "response": ["33", ""][: len(names)]},
    }


def test_export_gives_vimeo_players_optional_items_and_the_completion(design, tmp_path):
    vimeo = _vimeo(design)
    files = export_hemvip(design, tmp_path / "study", vimeo=vimeo)
    config = json.loads(files[0].read_text())
    urls = [s[1] for p in config["pages"] for s in p.get("stimuli", [])]
    assert urls and all(u.startswith("https://player.vimeo.com/video/") for u in urls)
    assert {u.split("/")[-1] for u in urls} <= set(vimeo.values())
    items = {q["name"]: q for q in config["pages"][-1]["questionnaire"]}
    assert items["comments"].get("optional") is True and "optional" not in items["age"]
    assert not items["comments"]["label"].startswith("*")
    assert all(len(p.get("stimuli", [])) <= 8 for p in config["pages"])
    code = [json.loads(line) for line in (tmp_path / "study" / "codes.jsonl").read_text().splitlines()]
    assert code == [{"testId": "study", "code": design.redirect.replace("{code}", design.completion_code)}]
    assert not list((tmp_path / "study").glob("codes*.json"))  # HEMVIP would take a .json for a config


def test_export_refuses_plain_urls_and_missing_ids(design, tmp_path):
    vimeo = _vimeo(design)
    plain = dict(vimeo, **{next(iter(vimeo)): "https://cdn.example/v.mp4"})
    with pytest.raises(ConfigError, match="Vimeo"):
        export_hemvip(design, tmp_path / "a", vimeo=plain)
    missing = dict(list(vimeo.items())[1:])
    with pytest.raises(ConfigError, match=f"no Vimeo video for 1 media: {next(iter(vimeo))}"):
        export_hemvip(design, tmp_path / "b", vimeo=missing)
    (tmp_path / "map.csv").write_text("id,vimeo\n" + "".join(f"{k},https://vimeo.com/{v}\n" for k, v in vimeo.items()))
    assert read_vimeo_map(tmp_path / "map.csv") == vimeo
    assert main(["study", "export-hemvip", str(design.folder), "--out", str(tmp_path / "c"), "--media-url", "x"]) == 2


def test_export_then_import_round_trip_through_hemvips_structure(design, tmp_path):
    files = export_hemvip(design, tmp_path / "study", vimeo=_vimeo(design))
    rng = np.random.default_rng(3)
    sessions = [_session_from_config(json.loads(f.read_text()), f"U{i}", rng) for i, f in enumerate(files[:3])]
    (tmp_path / "r.json").write_text(json.dumps(sessions))
    got = import_hemvip(design, [tmp_path / "r.json"])
    assert sorted(set(got["token"])) == ["U0", "U1", "U2"]
    # HEMVIP has no instructions' or audio check's answers: still, whoever reached the end finished
    flow = exclusions(design, got)
    assert flow["finished"].all() and (flow["answered"] < flow["pages"]).all()
    for s in sessions:
        mine = got[got["token"] == s["userId"]]
        for trial in s["trials"]:
            page_id = trial["id"].split("-")[0]
            answers = mine.set_index("page_id").loc[page_id, "answers"]
            if trial["type"] == "video":
                prompt = trial["id"].split("-")[1]
                for r in trial["responses"]:
                    assert answers[r["stimulus"]][prompt] == round(1 + 6 * int(r["score"]) / 100)
            else:
                left, right = (r["score"] for r in trial["responses"])
                assert answers["choice"] == (-1 if left else 1 if right else 0)


def _mongo_lines(sessions):
    return "\n".join(
        json.dumps({"_id": {"$oid": f"{i:024x}"}, **s, "ended": {"$date": "2022-05-01T10:00:00Z"}})
        for i, s in enumerate(sessions)
    )


def test_broken_video_reports_are_counted_and_both_json_forms_read(design, tmp_path, capsys):
    rng = np.random.default_rng(4)
    _, session = _simulate(design, 1, rng, "PID1")
    _, other = _simulate(design, 2, rng, "PID2")
    pc = next(t for t in session["trials"] if t["type"] == "videopc")
    for r in pc["responses"]:
        r["score"] = 99  # HEMVIP's "report a broken video"
    (tmp_path / "lines.json").write_text(_mongo_lines([session, other]) + "\n")
    (tmp_path / "array.json").write_text(json.dumps([session, other]))
    a = import_hemvip(design, [tmp_path / "lines.json"])
    b = import_hemvip(design, [tmp_path / "array.json"])
    pd.testing.assert_frame_equal(a, b)
    broken = a[a["page_id"] == pc["id"]].iloc[0]["answers"]
    assert broken == {"broken_video": True}
    table = pairwise_table(design, a)
    assert (
        pc["id"] not in set(table.get("page_id", []))
        and len(table) == sum(t["type"] == "videopc" for t in session["trials"] + other["trials"]) - 1
    )
    # the import and the analysis show them
    out = tmp_path / "responses.csv"
    assert main(["study", "import-hemvip", str(design.folder), str(tmp_path / "lines.json"), "--out", str(out)]) == 0
    assert "broken-video reports: 1" in capsys.readouterr().out
    frame = read_responses_csv(out)
    assert len(broken_videos(frame)) == 1 and broken_videos(frame)["page_id"].tolist() == [pc["id"]]
    sim = simulate_study([5, 4], participants=6, seed=1)
    report = analyse(sim.ratings, sim.pairwise, sim.exclusions, rounds=20)
    report.broken_videos = 1
    assert "Broken-video reports: 1" in report.markdown()


def test_duplicate_sessions_are_merged_when_identical_and_refused_otherwise(design, tmp_path, capsys):
    rng = np.random.default_rng(5)
    _, session = _simulate(design, 1, rng, "PID1")
    (tmp_path / "a.json").write_text(json.dumps([session]))
    (tmp_path / "b.json").write_text(json.dumps(session))
    once = import_hemvip(design, [tmp_path / "a.json"])
    twice = import_hemvip(design, [tmp_path / "a.json", tmp_path / "b.json"])
    pd.testing.assert_frame_equal(once, twice)
    _, again = _simulate(design, 1, rng, "PID1")  # the same userId, other answers: two people or a replay
    (tmp_path / "c.json").write_text(json.dumps(again))
    with pytest.raises(InputFileError, match="userId 'PID1'.*a.json: session 0"):
        import_hemvip(design, [tmp_path / "a.json", tmp_path / "c.json"])


def _mutations(session):
    trial = next(t for t in session["trials"] if t["type"] == "video")
    tid = trial["id"]

    def set_(path, value):
        def f(s):
            t = next(t for t in s["trials"] if t["id"] == tid)
            if path == "responses":
                t["responses"] = value
            elif path == "id":
                t["id"] = value
            else:
                t["responses"][0][path] = value
            return s

        return f

    return tid, {
        "responses a string": set_("responses", "abc"),
        "id a list": set_("id", [tid]),
        "score NaN": set_("score", math.nan),
        "score Infinity": set_("score", math.inf),
        "score 1e308": set_("score", 1e308),
        "score 1000": set_("score", 1000),
        "score -1000": set_("score", "-1000"),
        "time NaN": set_("time", math.nan),
        "time negative": set_("time", -5),
        "stimulus a list": set_("stimulus", ["x"]),
    }


def test_every_field_of_a_session_is_validated_naming_the_session_and_trial(design, tmp_path):
    import copy

    _, session = _simulate(design, 1, np.random.default_rng(6), "PID1")
    tid, cases = _mutations(session)
    for name, mutate in cases.items():
        bad = mutate(copy.deepcopy(session))
        (tmp_path / "bad.json").write_text(json.dumps(bad))  # NaN and Infinity as Python writes them
        with pytest.raises(InputFileError) as err:
            import_hemvip(design, [tmp_path / "bad.json"])
        text = str(err.value)
        assert "bad.json" in text and "session 0" in text, (name, text)
        if name != "id a list":
            assert tid in text, (name, text)
    for value in (["a"], ""):  # a list, empty
        (tmp_path / "bad.json").write_text(json.dumps(dict(session, userId=value)))
        with pytest.raises(InputFileError, match="session 0: userId"):
            import_hemvip(design, [tmp_path / "bad.json"])
    (tmp_path / "deep.json").write_text("[" * 5000 + "]" * 5000)
    with pytest.raises(InputFileError, match="nests"):
        import_hemvip(design, [tmp_path / "deep.json"])


def test_the_output_may_not_be_an_input_and_csv_cells_are_no_formulas(design, tmp_path, capsys):
    _, session = _simulate(design, 1, np.random.default_rng(7), "=cmd|' /C calc'!A0")
    (tmp_path / "r.json").write_text(json.dumps(session))
    key = (design.folder / "manifest.csv").read_bytes()
    for target in (design.folder / "manifest.csv", tmp_path / "r.json"):
        args = ["study", "import-hemvip", str(design.folder), str(tmp_path / "r.json"), "--out", str(target)]
        assert main([*args, "--force"]) == 2
        assert "is an input" in capsys.readouterr().err
    assert (design.folder / "manifest.csv").read_bytes() == key
    out = tmp_path / "responses.csv"
    assert main(["study", "import-hemvip", str(design.folder), str(tmp_path / "r.json"), "--out", str(out)]) == 0
    cells = pd.read_csv(out, dtype=str, keep_default_na=False)
    assert set(cells["token"]) == {"'=cmd|' /C calc'!A0"}
    an = tmp_path / "an"
    assert main(
        ["study", "analyse", str(design.folder), "--responses", str(out), "--out", str(an), "--rounds", "20"]
    ) in (0, 2)
    for f in an.glob("*.csv"):
        for value in pd.read_csv(f, dtype=str, keep_default_na=False).to_numpy().ravel():
            assert value[:1] not in ("=", "+", "@", "\t", "\r") and not (value.startswith("-") and not _num(value))


def _num(text):
    try:
        float(text)
        return True
    except ValueError:
        return False
