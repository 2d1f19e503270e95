"""A small stand-in for gesturekit.study.design in the server's tests: a study folder with fake media
(random bytes under opaque names) and the page sequence of the shared contract (instructions, audio check,
two rating pages, the second with an attention check, one pairwise page, a questionnaire, done)."""

from __future__ import annotations

import hashlib
import hmac
import json
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

SYSTEMS = ("alpha", "beta", "gamma")  # names that must never reach a participant
SPEECHES = ("speechone", "speechtwo")
PASSWORD = "researcher-secret"


@dataclass(frozen=True)
class Media:
    id: str
    path: Path
    kind: str


@dataclass(frozen=True)
class Page:
    id: str
    index: int
    kind: str
    media: tuple
    check: dict | None
    speech: str | None


def _hex(key: str, text: str, n: int = 12) -> str:
    return hmac.new(key.encode(), text.encode(), hashlib.sha256).hexdigest()[:n]


def hash_password(password: str) -> str:
    return hashlib.sha256(b"salt" + password.encode()).hexdigest()


def verify_password(password: str, stored: str) -> bool:
    return hmac.compare_digest(hash_password(password), stored)


def make_folder(folder: Path, rows: int = 4, max_failures: int = 0, video_bytes: int = 200_000) -> Path:
    """Write a fake study folder: media with random bytes, design.json as the contract describes."""
    rng = np.random.default_rng(0)
    (folder / "videos").mkdir(parents=True)
    (folder / "checks").mkdir()
    manifest = []
    for speech in SPEECHES:
        for system in SYSTEMS:
            mid = _hex("seed", f"{speech}:{system}")
            (folder / "videos" / f"{mid}.mp4").write_bytes(rng.bytes(video_bytes))
            manifest.append({"id": mid, "speech": speech, "system": system})
    check = _hex("seed", "check:overlay")
    (folder / "checks" / f"{check}.mp4").write_bytes(rng.bytes(video_bytes))
    beep = _hex("seed", "audio")
    (folder / "checks" / f"{beep}.wav").write_bytes(rng.bytes(20_000))
    design = {
        "title": "Gesture study",
        "instructions": "Watch each clip.\n\nRate it.",
        "rating": {
            "enabled": True,
            "scale": "likert7",
            "prompts": [{"id": "natural", "text": "Natural?"}, {"id": "sync", "text": "In sync?"}],
        },
        "pairwise": {"enabled": True, "prompt": "Which fits better?", "pairs": "all"},
        "attention": {"per_participant": 1, "kinds": ["overlay"], "max_failures": max_failures},
        "questionnaire": [
            {"id": "age", "text": "Your age", "type": "number", "min": 18, "max": 99},
            {"id": "comments", "text": "Comments", "type": "text", "optional": True},
        ],
        "participants": [{"participant": r} for r in range(1, rows + 1)],
        "completion": {"code": "C0MPLETE", "redirect": None},
        "researcher": {"password_sha256": hash_password(PASSWORD)},
        "_manifest": manifest,
        "_check": check,
        "_beep": beep,
        "_folder": str(folder),
    }
    (folder / "design.json").write_text(json.dumps(design))
    return folder


def load_design(folder: Path) -> SimpleNamespace:
    """The design with the attributes of gesturekit.study.design.StudyDesign that the server reads."""
    raw = json.loads((Path(folder) / "design.json").read_text())
    return SimpleNamespace(
        raw=raw,
        title=raw["title"],
        instructions=raw["instructions"],
        scale=raw["rating"]["scale"],
        prompts=tuple((p["id"], p["text"]) for p in raw["rating"]["prompts"]),
        pairwise_prompt=raw["pairwise"]["prompt"],
        max_failures=raw["attention"]["max_failures"],
        questionnaire=tuple(raw["questionnaire"]),
        participants=len(raw["participants"]),
        completion_code=raw["completion"]["code"],
        redirect=raw["completion"]["redirect"],
        password_hash=raw["researcher"]["password_sha256"],
    )


def media_index(design: SimpleNamespace) -> dict:
    design = design.raw
    folder = Path(design["_folder"])
    out = {m["id"]: Media(m["id"], folder / "videos" / f"{m['id']}.mp4", "stimulus") for m in design["_manifest"]}
    out[design["_check"]] = Media(design["_check"], folder / "checks" / f"{design['_check']}.mp4", "check")
    out[design["_beep"]] = Media(design["_beep"], folder / "checks" / f"{design['_beep']}.wav", "audio_check")
    return out


def participant_pages(design: SimpleNamespace, row: int) -> list:
    media = media_index(design)
    design = design.raw
    by_speech = {s: [media[m["id"]] for m in design["_manifest"] if m["speech"] == s] for s in SPEECHES}
    order = SPEECHES if row % 2 else SPEECHES[::-1]
    kinds: list = [("instructions", (), None, None)]
    kinds.append(("audio_check", (media[design["_beep"]],), {"media": design["_beep"], "expect": {"count": 4}}, None))
    kinds.append(("rating", tuple(by_speech[order[0]]), None, order[0]))
    check = {"media": design["_check"], "kind": "overlay", "expect": {"all": 1}}
    kinds.append(("rating", (*by_speech[order[1]], media[design["_check"]]), check, order[1]))
    kinds.append(("pairwise", tuple(by_speech[order[0]][:2]), None, order[0]))
    kinds.append(("questionnaire", (), None, None))
    kinds.append(("done", (), None, None))
    return [
        Page(_hex("seed", f"{row}:{i}"), i, kind, media_, check_, speech)
        for i, (kind, media_, check_, speech) in enumerate(kinds)
    ]


def check_answer(page: Page, answers: dict) -> bool | None:
    if page.check is None:
        return None
    if page.kind == "audio_check":
        return answers.get("count") == page.check["expect"]["count"]
    return all(v == 1 for v in answers[page.check["media"]].values())


def good_body(page: Page, fail: bool = False) -> dict:
    """A body a careful participant would send for ``page`` (``fail``: the attention check answered wrongly)."""
    events = [
        {"t": 0.1 * i, "kind": k, "media": m.id, "at": 0.0} for i, m in enumerate(page.media) for k in ("play", "ended")
    ]
    if page.kind == "rating":
        answers = {m.id: {"natural": 5, "sync": 4} for m in page.media}
        if page.check is not None:
            answers[page.check["media"]] = {"natural": 3 if fail else 1, "sync": 1}
    elif page.kind == "pairwise":
        answers = {"choice": 1}
    elif page.kind == "audio_check":
        answers = {"count": 2 if fail else 4}
    elif page.kind == "questionnaire":
        answers = {"age": 30}
    else:
        answers = {}
    return {"answers": answers, "events": events, "elapsed_s": 12.5}
