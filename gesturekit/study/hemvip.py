"""HEMVIP interop: a study as HEMVIP experiment configs, and HEMVIP results as our responses.

The target is HEMVIP's ``genea2022`` branch (github.com/jonepatr/hemvip), the version with
``videopc`` pages, the "report a broken video" button and the Prolific completion: its players are
Vimeo players, so every media is referred to by the Vimeo video the researcher uploaded it to (a
mapping, one Vimeo id per media id); plain file URLs never play there and are refused. A page shows at
most :data:`MAX_VIDEOS` videos (HEMVIP stops on more). The completion goes to ``codes.jsonl`` (the
document HEMVIP's ``codes`` collection needs: ``/save`` sends the participant to its ``code``).

HEMVIP (the GENEA challenges' evaluation platform, built on webMUSHRA) reads one JSON config
per participant: ``{"testname", "remoteService", "pages": [...]}`` with pages of type
``generic`` (text), ``video`` (every video of a page rated on a 0..100 slider, one question per
page) and ``videopc`` (two videos, left / right / equal), ending with a ``finish`` page that holds
the questionnaire. Its results are webMUSHRA sessions: ``{"testId", "userId", "trials": [{"type",
"id", "responses": [{"stimulus", "score", "time"}]}], "participant": {"name": [...], "response":
[...]}}``.

:func:`export_hemvip` writes a config per order.csv row from :func:`participant_pages`: a rating
page becomes one ``video`` page per prompt (page id ``<page id>-<prompt id>``), a pairwise page a
``videopc`` page, the questionnaire the finish page's. The audio check has no HEMVIP page and is
left out. Check videos are referred to like stimuli; the checks are scored after import
(:func:`check_answer`), not by HEMVIP. Optional questionnaire items carry ``optional: true``.

:func:`import_hemvip` reads results back into the frame of ``Store.responses_frame()``, so the
analysis runs on it unchanged. A 0..100 score is kept on ``slider100`` designs and mapped to
``round(1 + 6 score / 100)`` on ``likert7`` ones; a pairwise answer (left, right, equal) becomes
-1, +1 or 0 (a numeric score of -2..2 is kept as it is); a videopc page whose scores are 99 (HEMVIP's
"report a broken video") becomes ``{"broken_video": true}``, counted by the analysis and not a
preference. Results are read as a JSON array (HEMVIP's ``tools/export_data.py``), one session object,
or JSON lines (``mongoexport``). Every field naming a session and a trial is checked, and the error
names both; a session listed twice is kept once when identical, refused when not.
"""

from __future__ import annotations

import html
import json
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .._arguments import checks_arguments
from .._io import atomic_write, csv_safe
from ..errors import ConfigError, GestureKitError, InputFileError, OutputError
from ..limits import JSON_MB, check_regular, describe_bytes, parse_json
from .design import Page, StudyDesign, participant_pages

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "RESPONSE_COLUMNS",
    "HEMVIP_VERSION",
    "MAX_VIDEOS",
    "BROKEN_SCORE",
    "hemvip_config",
    "export_hemvip",
    "import_hemvip",
    "read_vimeo_map",
    "write_responses_csv",
]

#: the HEMVIP the export is made for, and the import reads
HEMVIP_VERSION = "jonepatr/hemvip, branch genea2022"
#: HEMVIP refuses a page with more videos than this
MAX_VIDEOS = 8
#: HEMVIP's score for "report a broken video" on a videopc page
BROKEN_SCORE = 99
_VIMEO_ID = re.compile(r"^(?:https?://(?:player\.)?vimeo\.com/(?:video/)?)?(\d{1,12})(?:[/?#].*)?$")
_PLAYER = "https://player.vimeo.com/video/{}"

RESPONSE_COLUMNS = ["token", "row", "page_id", "page_index", "kind", "answers", "elapsed_s", "submitted_at"]


def _question_item(q: dict) -> dict:
    item: dict[str, Any] = {"name": q["id"], "label": q["text"]}
    if q.get("optional"):
        item["optional"] = True
    if q["type"] == "number":
        item.update(type="number", min=q.get("min", 0), max=q.get("max", 100), default=q.get("min", 0))
    elif q["type"] == "choice":
        item.update(type="options", response=[{"value": o, "label": o} for o in q["options"]])
    else:
        item["type"] = "text"
    return item


@checks_arguments
def read_vimeo_map(path: str | os.PathLike) -> dict[str, str]:
    """A CSV of ``id,vimeo`` (a media id and its Vimeo video: the number or its vimeo.com URL) as id -> number.

    Raises
    ------
    InputFileError
        Not a regular file, no ``id`` and ``vimeo`` columns, or a row that names no Vimeo video.
    """
    import csv

    path = Path(path)
    check_regular(path, error=InputFileError)
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    if rows and not {"id", "vimeo"} <= set(rows[0]):
        raise InputFileError("needs the columns id and vimeo (the media id, its Vimeo video)", path=path)
    return {r["id"]: _vimeo_id(r["vimeo"], r["id"], path) for r in rows}


def _vimeo_id(value: Any, media: str, path: Path | None = None) -> str:
    match = _VIMEO_ID.match(str(value).strip())
    if match is None:
        raise ConfigError(
            f"media {media}: {value!r} is no Vimeo video. HEMVIP ({HEMVIP_VERSION}) plays every video with "
            "Vimeo's player, which plays Vimeo videos only: a plain file URL would never play. Upload the "
            "videos to Vimeo and give each media id its Vimeo id or https://vimeo.com/<id> URL",
            path=path,
        )
    return match.group(1)


@checks_arguments
def hemvip_config(design: StudyDesign, row: int, *, vimeo: dict[str, str]) -> dict:
    """The HEMVIP config of one participant row (see the module documentation).

    Parameters
    ----------
    design : StudyDesign
    row : int
        1-based row of order.csv.
    vimeo : dict
        Media id -> its Vimeo video id (every media the row shows).

    Raises
    ------
    ConfigError
        A media without a Vimeo video, or a page with more than :data:`MAX_VIDEOS` videos.
    """
    pages = participant_pages(design, row)
    missing = sorted({m.id for p in pages if p.kind in ("rating", "pairwise") for m in p.media} - set(vimeo))
    if missing:
        raise ConfigError(
            f"no Vimeo video for {len(missing)} media: {', '.join(missing[:10])}"
            + (" ..." if len(missing) > 10 else "")
            + "; give every media id of the study its Vimeo id"
        )
    media_pages = [p for p in pages if p.kind in ("rating", "pairwise")]
    total = sum(len(design.prompts) if p.kind == "rating" else 1 for p in media_pages)
    out: list[dict] = []
    n = 0
    for page in pages:
        if page.kind in ("rating", "pairwise") and len(page.media) > MAX_VIDEOS:
            raise ConfigError(
                f"row {row}: a page shows {len(page.media)} videos; HEMVIP stops on more than {MAX_VIDEOS}"
            )
        stimuli = [[m.id, _PLAYER.format(vimeo[m.id])] for m in page.media if page.kind in ("rating", "pairwise")]
        if page.kind == "instructions":
            content = html.escape(design.instructions).replace("\n", "<br>")
            out.append({"type": "generic", "id": page.id, "name": design.title, "content": content})
        elif page.kind == "rating":
            for prompt_id, text in design.prompts:
                n += 1
                out.append(
                    {
                        "type": "video",
                        "id": f"{page.id}-{prompt_id}",
                        "name": f"Page {n} of {total}",
                        "content": "Rate the videos shown below",
                        "question": text,
                        "stimuli": stimuli,
                    }
                )
        elif page.kind == "pairwise":
            n += 1
            q = design.pairwise_prompt
            out.append(
                {"type": "videopc", "id": page.id, "name": f"Page {n} of {total}", "content": q, "question": q}
                | {"stimuli": stimuli}
            )
    finish = {
        "type": "finish",
        "name": "Thank you",
        "content": f"Thank you for your participation! Your completion code: {design.completion_code}",
        "showResults": False,
        "writeResults": True,
        "questionnaire": [_question_item(dict(q)) for q in design.questionnaire],
    }
    return {
        "testname": design.title,
        "stopOnErrors": True,
        "showButtonPreviousPage": False,
        "remoteService": "/save",
        "remoteFailService": "/fail",
        "pages": out + [finish],
    }


def _completion(design: StudyDesign) -> str:
    """Where HEMVIP sends a participant who finished: the redirect with the code, or the code itself."""
    if design.redirect:
        return design.redirect.replace("{code}", design.completion_code)
    return design.completion_code


@checks_arguments
def export_hemvip(
    design: StudyDesign, out: str | os.PathLike, *, vimeo: dict[str, str], overwrite: bool = False
) -> list[Path]:
    """Write ``out/participant_NNNN.json``, a HEMVIP config per order.csv row (``design.participants``).

    ``out`` is HEMVIP's ``configs/<test id>`` (its name is the test id). Besides the configs,
    ``out/codes.jsonl`` holds the ``codes`` document of the test id (import it with ``mongoimport``);
    it does not end in ``.json``, as HEMVIP hands out every ``.json`` there as a config.

    Parameters
    ----------
    vimeo : dict
        Media id -> Vimeo video (its number, or a vimeo.com URL); every media of the study.

    Returns
    -------
    list of Path
        The configs, in row order (HEMVIP hands them out in sorted order).
    """
    out = Path(out)
    ids = {k: _vimeo_id(v, k) for k, v in vimeo.items()}
    configs = [hemvip_config(design, row, vimeo=ids) for row in range(1, design.participants + 1)]
    files = [out / f"participant_{row:04d}.json" for row in range(1, design.participants + 1)]
    existing = [f for f in [*files, out / "codes.jsonl"] if f.exists()]
    if existing and not overwrite:
        raise OutputError("exists; pass --force (overwrite=True) to replace the configs", path=existing[0])
    out.mkdir(parents=True, exist_ok=True)
    for config, path in zip(configs, files):
        _write_bytes(path, (json.dumps(config, indent=1) + "\n").encode())
    code = {"testId": out.name, "code": _completion(design)}
    _write_bytes(out / "codes.jsonl", (json.dumps(code) + "\n").encode())
    return files


def _write_bytes(path: Path, data: bytes) -> Path:
    return atomic_write(path, lambda f: f.write(data), overwrite=True)


def _fail(path: Path, where: str, problem: str) -> InputFileError:
    return InputFileError(f"{where}: {problem}", path=path)


def _number(value: Any, path: Path, where: str, what: str) -> float:
    """A finite number (or its text, as HEMVIP's sliders give it)."""
    if isinstance(value, bool) or value is None or not isinstance(value, (int, float, str)):
        raise _fail(path, where, f"{what} must be a number, got {_shown(value)}")
    try:
        number = float(value)
    except ValueError:
        raise _fail(path, where, f"{what} must be a number, got {_shown(value)}") from None
    if not math.isfinite(number):
        raise _fail(path, where, f"{what} must be finite, got {_shown(value)}")
    return number


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _rating_value(design: StudyDesign, score: float, path: Path, where: str) -> int:
    if not 0 <= score <= 100:
        raise _fail(path, where, f"a slider score is 0..100, got {score:g}")
    if design.scale == "slider100":
        return int(round(score))
    return int(round(1 + 6 * score / 100))


def _pairwise_value(responses: list, page: Page, path: Path, where: str) -> int | None:
    """-1 (left), 1 (right), 0 (equal), or None: HEMVIP's broken-video report (every score 99)."""
    by_id = {r["stimulus"]: r["score"] for r in responses}
    if set(by_id) != {m.id for m in page.media}:
        raise _fail(path, where, f"the responses name {sorted(by_id)}, not this page's two videos")
    left, right = (by_id[m.id] for m in page.media)
    if isinstance(left, bool) and isinstance(right, bool):
        return -1 if left and not right else 1 if right and not left else 0
    values = [_number(v, path, where, "a pairwise score") for v in (left, right)]
    if values == [BROKEN_SCORE, BROKEN_SCORE]:
        return None
    if values[0] not in (-2, -1, 0, 1, 2):
        raise _fail(path, where, f"a pairwise score must be -2..2, true/false or {BROKEN_SCORE}, got {left!r}")
    return int(values[0])


def _read_sessions(path: Path) -> list[tuple[str, Any]]:
    """The sessions of one results file: (where, session) for a JSON array, one object, or JSON lines."""
    size = check_regular(path, error=InputFileError)
    cap = JSON_MB.value() * 1e6
    if size > cap:
        raise InputFileError(f"is {describe_bytes(size)}, beyond {describe_bytes(cap)} for a JSON file", path=path)
    with open(path, "rb") as f:
        raw = f.read()
    try:
        data = parse_json(raw, error=InputFileError, path=path)
    except GestureKitError as whole:
        lines = [line for line in raw.splitlines() if line.strip()]
        if len(lines) < 2 or "nests" in str(whole):
            raise InputFileError(f"not a HEMVIP result JSON ({whole.problem})", path=path) from None
        out = []
        for i, line in enumerate(lines):  # mongoexport: one document per line
            what = f"line {i + 1} "
            out.append((f"session {i} (line {i + 1})", parse_json(line, what=what, error=InputFileError, path=path)))
        return out
    return [(f"session {k}", session) for k, session in enumerate(data if isinstance(data, list) else [data])]


@checks_arguments
def import_hemvip(
    design: StudyDesign, results: Sequence[str | os.PathLike], *, notes: list[str] | None = None
) -> pd.DataFrame:
    """HEMVIP result files as responses: the columns of ``Store.responses_frame()``.

    Parameters
    ----------
    design : StudyDesign
        The design the configs were exported from (page ids identify the row).
    results : sequence of path
        JSON files: an array of sessions, one session, or one session per line (``mongoexport``).
    notes : list, optional
        Receives what was merged, in words (a session listed twice).

    Returns
    -------
    pandas.DataFrame
        ``token`` (HEMVIP's userId), ``row``, ``page_id``, ``page_index``, ``kind`` (rating, pairwise,
        questionnaire), ``answers`` (dict as the server stores them; ``{"broken_video": true}`` for a
        broken-video report), ``elapsed_s``, ``submitted_at`` (None: HEMVIP does not record it); one row
        per page, in page order.

    Raises
    ------
    InputFileError
        Naming the file, the session and the trial: a field of the wrong shape or out of range, a page
        of another study, or one userId on two different sessions.
    """
    import pandas as pd

    pages: dict[str, tuple[int, Page]] = {}
    for row in range(1, design.participants + 1):
        for page in participant_pages(design, row):
            pages[page.id] = (row, page)
    records = []
    seen: dict[str, tuple[str, str]] = {}  # userId -> (where first, its records as JSON)
    for name in results:
        path = Path(name)
        for where, session in _read_sessions(path):
            mine = _session_records(design, pages, session, path, where)
            token = mine[0]["token"] if mine else str(session.get("userId"))
            digest = json.dumps(mine, sort_keys=True, default=str)
            place = f"{path.name}: {where}"
            if token in seen:
                first, before = seen[token]
                if before != digest:
                    raise InputFileError(
                        f"{where}: userId {token!r} is also {first}, with other answers: two people with one "
                        "id, or one person twice; keep the session to count and import again",
                        path=path,
                    )
                if notes is not None:
                    notes.append(f"userId {token!r}: {place} repeats {first}; counted once")
                continue
            seen[token] = (place, digest)
            records += mine
    frame = pd.DataFrame(records, columns=RESPONSE_COLUMNS)
    return frame.sort_values(["token", "page_index"], kind="stable").reset_index(drop=True)


def _session_records(design: StudyDesign, pages: dict, session: Any, path: Path, where: str) -> list[dict]:
    if not isinstance(session, dict) or not isinstance(session.get("trials"), list):
        raise _fail(path, where, "not a HEMVIP session (no list of trials)")
    user = session.get("userId")
    if not isinstance(user, (str, int)) or isinstance(user, bool) or str(user).strip() == "":
        raise _fail(path, where, f"userId must be a non-empty text, got {_shown(user)}")
    token = str(user)
    found: dict[str, dict] = {}
    row_of: set[int] = set()
    prompts = {p for p, _ in design.prompts}
    for k, trial in enumerate(session["trials"]):
        if not isinstance(trial, dict) or not isinstance(trial.get("id"), str):
            raise _fail(path, where, f"trial {k} has no text id: {_shown(trial)}")
        tid = trial["id"]
        at = f"{where}, trial {tid!r}"
        page_id, _, prompt = tid.partition("-")
        if page_id not in pages:
            raise _fail(path, where, f"the page {tid!r} is not a page of this design")
        row, page = pages[page_id]
        row_of.add(row)
        responses = trial.get("responses")
        if responses is None:
            responses = []
        if not isinstance(responses, list) or not all(
            isinstance(r, dict) and isinstance(r.get("stimulus"), str) and "score" in r for r in responses
        ):
            raise _fail(path, at, f"responses must be a list of {{stimulus, score, time}}, got {_shown(responses)}")
        rec = found.setdefault(page_id, {"page": page, "row": row, "answers": {}, "elapsed_s": 0.0})
        times = [_number(r.get("time", 0), path, at, "a time (ms)") for r in responses]
        if any(t < 0 for t in times):
            raise _fail(path, at, f"a time must be 0 or more milliseconds, got {min(times):g}")
        rec["elapsed_s"] += max(times, default=0.0) / 1000
        if page.kind == "rating":
            if prompt not in prompts:
                raise _fail(path, where, f"{tid!r} names no prompt of the design")
            media = {m.id for m in page.media}
            for r in responses:
                if r["stimulus"] not in media:
                    raise _fail(path, at, f"the stimulus {r['stimulus']!r} is not on this page")
                value = _rating_value(design, _number(r["score"], path, at, "a score"), path, at)
                rec["answers"].setdefault(r["stimulus"], {})[prompt] = value
        elif page.kind == "pairwise":
            choice = _pairwise_value(responses, page, path, at)
            rec["answers"] = {"broken_video": True} if choice is None else {"choice": choice}
    if len(row_of) > 1:
        raise _fail(path, where, f"pages of several participants' rows {sorted(row_of)}")
    out = [
        {
            "token": token,
            "row": rec["row"],
            "page_id": pid,
            "page_index": rec["page"].index,
            "kind": rec["page"].kind,
            "answers": rec["answers"],
            "elapsed_s": round(rec["elapsed_s"], 3),
            "submitted_at": None,
        }
        for pid, rec in found.items()
    ]
    questionnaire = _questionnaire(design, session.get("participant"))
    if questionnaire is not None and row_of:
        row = row_of.pop()
        page = next(p for p in participant_pages(design, row) if p.kind == "questionnaire")
        out.append(
            {
                "token": token,
                "row": row,
                "page_id": page.id,
                "page_index": page.index,
                "kind": "questionnaire",
                "answers": questionnaire,
                "elapsed_s": 0.0,
                "submitted_at": None,
            }
        )
    return out


def _questionnaire(design: StudyDesign, participant: Any) -> dict | None:
    """webMUSHRA's ``participant`` (``{"name": [...], "response": [...]}``) as ``{question id: value}``."""
    if not design.questionnaire or not isinstance(participant, dict):
        return None
    names, values = participant.get("name") or [], participant.get("response") or []
    if not isinstance(names, list) or not isinstance(values, list):
        return None
    given = {n: v for n, v in zip(names, values) if isinstance(n, str) and isinstance(v, (str, int, float))}
    answers: dict[str, Any] = {}
    for q in design.questionnaire:
        if q["id"] not in given:
            continue
        value = given[q["id"]]
        if q["type"] == "number":
            try:
                number = float(value)
            except (TypeError, ValueError):
                continue
            if not math.isfinite(number):
                continue
            value = int(number) if number.is_integer() else number
        answers[q["id"]] = value
    return answers


@checks_arguments
def write_responses_csv(frame: pd.DataFrame, out: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write responses as CSV (``answers`` as JSON text); refuses to replace a file without ``overwrite``."""
    out = Path(out)
    if out.exists() and not overwrite:
        raise OutputError("exists; pass --force (overwrite=True) to replace it", path=out)
    if out.suffix.lower() != ".csv":
        raise ConfigError(f"the responses file must end in .csv, got {out.name}")
    table = csv_safe(frame).assign(answers=[json.dumps(a, sort_keys=True) for a in frame["answers"]])
    return _write_bytes(out, table.to_csv(index=False, lineterminator="\n").encode())
