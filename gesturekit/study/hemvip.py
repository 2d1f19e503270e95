"""HEMVIP interop: a study as HEMVIP experiment configs, and HEMVIP results as our responses.

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
left out. Media are referred to by id (``URL/<id>.mp4``), check videos like stimuli; the checks are
scored after import (:func:`check_answer`), not by HEMVIP.

:func:`import_hemvip` reads results back into the frame of ``Store.responses_frame()``, so the
analysis runs on it unchanged. A 0..100 score is kept on ``slider100`` designs and mapped to
``round(1 + 6 score / 100)`` on ``likert7`` ones; a pairwise answer (left, right, equal) becomes
-1, +1 or 0 (a numeric score of -2..2 is kept as it is).
"""

from __future__ import annotations

import html
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .._io import atomic_write
from ..errors import ConfigError, InputFileError, OutputError
from .design import Page, StudyDesign, participant_pages

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["RESPONSE_COLUMNS", "hemvip_config", "export_hemvip", "import_hemvip", "write_responses_csv"]

RESPONSE_COLUMNS = ["token", "row", "page_id", "page_index", "kind", "answers", "elapsed_s", "submitted_at"]


def _question_item(q: dict) -> dict:
    item: dict[str, Any] = {"name": q["id"], "label": ("" if q.get("optional") else "*") + q["text"]}
    if q["type"] == "number":
        item.update(type="number", min=q.get("min", 0), max=q.get("max", 100), default=q.get("min", 0))
    elif q["type"] == "choice":
        item.update(type="options", response=[{"value": o, "label": o} for o in q["options"]])
    else:
        item["type"] = "text"
    return item


def hemvip_config(design: StudyDesign, row: int, *, media_url: str = "/media") -> dict:
    """The HEMVIP config of one participant row (see the module documentation).

    Parameters
    ----------
    design : StudyDesign
    row : int
        1-based row of order.csv.
    media_url : str
        URL prefix of the media files (``<media_url>/<id>.mp4``).
    """
    pages = participant_pages(design, row)
    base = media_url.rstrip("/")
    media_pages = [p for p in pages if p.kind in ("rating", "pairwise")]
    total = sum(len(design.prompts) if p.kind == "rating" else 1 for p in media_pages)
    out: list[dict] = []
    n = 0
    for page in pages:
        stimuli = [[m.id, f"{base}/{m.id}.mp4"] for m in page.media]
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


def export_hemvip(
    design: StudyDesign, out: str | os.PathLike, *, media_url: str = "/media", overwrite: bool = False
) -> list[Path]:
    """Write ``out/participant_NNNN.json``, a HEMVIP config per order.csv row (``design.participants``).

    Returns
    -------
    list of Path
        The files, in row order (HEMVIP hands them out in sorted order).
    """
    out = Path(out)
    files = [out / f"participant_{row:04d}.json" for row in range(1, design.participants + 1)]
    existing = [f for f in files if f.exists()]
    if existing and not overwrite:
        raise OutputError("exists; pass --force (overwrite=True) to replace the configs", path=existing[0])
    out.mkdir(parents=True, exist_ok=True)
    for row, path in enumerate(files, start=1):
        _write_bytes(path, (json.dumps(hemvip_config(design, row, media_url=media_url), indent=1) + "\n").encode())
    return files


def _write_bytes(path: Path, data: bytes) -> Path:
    return atomic_write(path, lambda f: f.write(data), overwrite=True)


def _score(value: Any, path: Path, where: str) -> float:
    if isinstance(value, bool) or value is None:
        raise InputFileError(f"{where}: a score must be a number, got {value!r}", path=path)
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputFileError(f"{where}: a score must be a number, got {value!r}", path=path) from None


def _rating_value(design: StudyDesign, score: float) -> int:
    if design.scale == "slider100":
        return int(round(score))
    return int(round(1 + 6 * score / 100))


def _pairwise_value(responses: list, page: Page, path: Path, where: str) -> int:
    by_id = {r.get("stimulus"): r.get("score") for r in responses if isinstance(r, dict)}
    left, right = (by_id.get(m.id) for m in page.media)
    if isinstance(left, bool) and isinstance(right, bool):
        return -1 if left and not right else 1 if right and not left else 0
    value = _score(left, path, where)
    if value not in (-2, -1, 0, 1, 2):
        raise InputFileError(f"{where}: a pairwise score must be -2..2 or true/false, got {left!r}", path=path)
    return int(value)


def import_hemvip(design: StudyDesign, results: Sequence[str | os.PathLike]) -> pd.DataFrame:
    """HEMVIP result files as responses: the columns of ``Store.responses_frame()``.

    Parameters
    ----------
    design : StudyDesign
        The design the configs were exported from (page ids identify the row).
    results : sequence of path
        JSON files, each a session object or a list of them.

    Returns
    -------
    pandas.DataFrame
        ``token`` (HEMVIP's userId), ``row``, ``page_id``, ``page_index``, ``kind`` (rating, pairwise,
        questionnaire), ``answers`` (dict as the server stores them), ``elapsed_s``, ``submitted_at``
        (None: HEMVIP does not record it); one row per page, in page order.
    """
    import pandas as pd

    pages: dict[str, tuple[int, Page]] = {}
    for row in range(1, design.participants + 1):
        for page in participant_pages(design, row):
            pages[page.id] = (row, page)
    records = []
    for name in results:
        path = Path(name)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputFileError(f"not a HEMVIP result JSON ({exc})", path=path) from None
        for k, session in enumerate(data if isinstance(data, list) else [data]):
            records += _session_records(design, pages, session, path, f"session {k}")
    frame = pd.DataFrame(records, columns=RESPONSE_COLUMNS)
    return frame.sort_values(["token", "page_index"], kind="stable").reset_index(drop=True)


def _session_records(design: StudyDesign, pages: dict, session: Any, path: Path, where: str) -> list[dict]:
    if not isinstance(session, dict) or not isinstance(session.get("trials"), list):
        raise InputFileError(f"{where}: not a HEMVIP session (no trials)", path=path)
    token = str(session.get("userId") or f"{path.stem}-{where.split()[-1]}")
    found: dict[str, dict] = {}
    row_of: set[int] = set()
    for trial in session["trials"]:
        tid = str(trial.get("id", "")) if isinstance(trial, dict) else ""
        page_id, _, prompt = tid.partition("-")
        if page_id not in pages:
            raise InputFileError(f"{where}: the page {tid!r} is not a page of this design", path=path)
        row, page = pages[page_id]
        row_of.add(row)
        responses = trial.get("responses") or []
        rec = found.setdefault(page_id, {"page": page, "row": row, "answers": {}, "elapsed_s": 0.0})
        times = [r.get("time") for r in responses if isinstance(r, dict)]
        rec["elapsed_s"] += max([float(t) / 1000 for t in times if isinstance(t, (int, float))], default=0.0)
        if page.kind == "rating":
            if prompt not in {p for p, _ in design.prompts}:
                raise InputFileError(f"{where}: {tid!r} names no prompt of the design", path=path)
            for r in responses:
                value = _rating_value(design, _score(r.get("score"), path, f"{where}, {tid}"))
                rec["answers"].setdefault(str(r.get("stimulus")), {})[prompt] = value
        elif page.kind == "pairwise":
            rec["answers"] = {"choice": _pairwise_value(responses, page, path, f"{where}, {tid}")}
    if len(row_of) > 1:
        raise InputFileError(f"{where}: pages of several participants' rows {sorted(row_of)}", path=path)
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
    given = dict(zip(names, values))
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
            value = int(number) if number.is_integer() else number
        answers[q["id"]] = value
    return answers


def write_responses_csv(frame: pd.DataFrame, out: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write responses as CSV (``answers`` as JSON text); refuses to replace a file without ``overwrite``."""
    out = Path(out)
    if out.exists() and not overwrite:
        raise OutputError("exists; pass --force (overwrite=True) to replace it", path=out)
    if out.suffix.lower() != ".csv":
        raise ConfigError(f"the responses file must end in .csv, got {out.name}")
    table = frame.assign(answers=[json.dumps(a, sort_keys=True) for a in frame["answers"]])
    return _write_bytes(out, table.to_csv(index=False, lineterminator="\n").encode())
