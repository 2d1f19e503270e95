"""A study's design (``design.json``): what participants see, in which order, and the checks.

``design.json`` sits in a stimuli folder (:mod:`gesturekit.study.stimuli`) beside ``manifest.csv``,
``order.csv`` and ``study.json``; like them it is kept from participants. Its fields::

    format, version      "gesturekit-study-design", 1
    seed                 the study's seed (from study.json): the check media and the layout follow from it
    secret               64 random hex digits: page ids are HMACs keyed by it (so that a participant
                         who knows the seed still cannot forge one), and the completion code
    title, instructions  shown on the first page (the paper's instructions by default)
    rating               enabled, scale ("likert7" 1..7 or "slider100" 0..100), prompts [{id, text}]
    pairwise             enabled, prompt, pairs ("all" or pairs per speech); answers -2 (clearly
                         left) .. +2 (clearly right)
    attention            per_participant, kinds (mismatched_audio, overlay), max_failures
    audio_check          enabled, id, file, beeps (the answer)
    checks               the attention-check videos: [{id, kind, speech, file}]
    questionnaire        [{id, text, type (number|text|choice), min, max, options, optional}]
    participants         how many rows of order.csv are served
    completion           code, redirect (a URL or null)
    researcher           password_hash (scrypt, see :func:`hash_password`) or null

:func:`load_design` validates every field, naming the file and the field in its errors;
:func:`participant_pages` lays out one participant's pages, the same for the same design and row.
"""

from __future__ import annotations

import csv
import hashlib
import hmac
import itertools
import json
import os
import re
import secrets
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._arguments import checks_arguments
from .._io import atomic_write
from ..errors import ConfigError, OutputError
from ..limits import read_json
from ._fields import ID_RE, Reader, finite, media_file, media_id, question, shown

__all__ = [
    "FORMAT",
    "SCALES",
    "CHECK_KINDS",
    "DEFAULT_PROMPTS",
    "Media",
    "Page",
    "StudyDesign",
    "default_instructions",
    "load_design",
    "init_study",
    "participant_pages",
    "media_index",
    "check_answer",
    "hash_password",
    "verify_password",
]

FORMAT = "gesturekit-study-design"
VERSION = 1
SCALES = ("likert7", "slider100")
CHECK_KINDS = ("mismatched_audio", "overlay")
SCALE_RANGE = {"likert7": (1, 7), "slider100": (0, 100)}
# answers that pass a check: "every prompt at the bottom" / "sync poor" / "left"
_OVERLAY_MAX = {"likert7": 1, "slider100": 10}
_MISMATCH_MAX = {"likert7": 3, "slider100": 30}
DEFAULT_PROMPTS = (
    {"id": "natural", "text": "The clip appears natural and the gesture follows the speaking style of the speaker."},
    {"id": "sync", "text": "The gesture and the audio are well synchronized."},
)
DEFAULT_QUESTIONNAIRE = (
    {"id": "age", "text": "Your age", "type": "number", "min": 18, "max": 99},
    {"id": "comments", "text": "Comments", "type": "text", "optional": True},
)
_SCRYPT = {"n": 2**14, "r": 8, "p": 1}


@checks_arguments
def default_instructions(animations: int, scale: str = "likert7", *, checks: bool = False) -> str:
    """The paper's instructions (its supplementary material), for ``animations`` animations per speech.

    Parameters
    ----------
    animations : int
        Videos per speech (the study's systems).
    scale : str
        ``"likert7"`` (the paper's seven points) or ``"slider100"``.
    checks : bool
        Some rating pages show one video more (an attention check): the count says so.
    """
    count = f"{animations} or {animations + 1}" if checks else f"{animations}"
    answer = "a seven-point scale" if scale == "likert7" else "a slider from 0 to 100"
    return (
        "The purpose of this user study is to measure the synthesis quality of AI-based methods that "
        "automatically generate the 3D body and hand gestures of a virtual character from speech input. "
        f"For each audio clip, you will see {count} different animations that consist mostly of synthetic "
        "videos but may also include direct copies of the actual performance. After watching each clip, you "
        f"will be asked to provide responses to two prompts using {answer}. The prompts are: "
        f"{DEFAULT_PROMPTS[0]['text']} {DEFAULT_PROMPTS[1]['text']} "
        "Please ignore the quality of the facial expression of the virtual character. "
        "Each synthesis method tries to mimic the gesturing style of the speaker. "
        "Please watch every video to its end, with sound on. Thank you for your participation."
    )


# ---- the design ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Media:
    """A file the study may serve: ``id`` opaque, ``path`` in the study folder, ``kind`` one of
    ``"stimulus"``, ``"check"`` (an attention-check video) or ``"audio_check"`` (the beeps)."""

    id: str
    path: Path
    kind: str


@dataclass(frozen=True)
class Page:
    """One page of a participant's sequence.

    Attributes
    ----------
    id : str
        Opaque: HMAC(design.json's ``secret``, ``"row:index"``), 12 hex digits.
    index : int
        0-based position in the sequence.
    kind : str
        ``instructions``, ``audio_check``, ``rating``, ``pairwise``, ``questionnaire`` or ``done``.
    media : tuple of Media
        rating: every stimulus of one speech (perhaps with one attention-check video mixed in);
        pairwise: (left, right); audio_check: the beeps.
    check : dict or None
        ``{"media": id, "kind": ..., "expect": {key: {"min": a, "max": b}}}`` (server side only).
    speech : str or None
        The speech of a rating or pairwise page (server side only).
    """

    id: str
    index: int
    kind: str
    media: tuple[Media, ...] = ()
    check: dict | None = None
    speech: str | None = None


@dataclass(frozen=True)
class StudyDesign:
    """A validated ``design.json`` with the stimuli folder's order (see the module documentation).

    ``raw`` is the file's content; ``order`` maps an order.csv row (1-based) to its speeches in turn,
    each ``(speech, stimulus ids in their positions)``; ``stimuli`` maps a stimulus id to
    ``(speech, file)``; ``checks`` maps (speech, kind) to a check video's Media.
    """

    folder: Path
    raw: Mapping[str, Any]
    seed: int
    secret: str
    title: str
    instructions: str
    rating: bool
    scale: str
    prompts: tuple[tuple[str, str], ...]
    pairwise: bool
    pairwise_prompt: str
    pairs: int | None
    attention: int
    check_kinds: tuple[str, ...]
    max_failures: int
    audio_check: Media | None
    beeps: int | None
    questionnaire: tuple[Mapping[str, Any], ...]
    participants: int
    completion_code: str
    redirect: str | None
    password_hash: str | None
    order: Mapping[int, tuple[tuple[str, tuple[str, ...]], ...]]
    stimuli: Mapping[str, tuple[str, str]]
    checks: Mapping[tuple[str, str], Media]


def _read_csv(path: Path) -> list[dict[str, str]]:
    try:
        with open(path, newline="", encoding="utf-8") as f:
            return list(csv.DictReader(f))
    except FileNotFoundError:
        raise ConfigError("is missing: the study folder needs what `gesturekit stimuli` writes", path=path) from None


def _folder_plan(folder: Path) -> tuple[dict[str, tuple[str, str]], dict[int, tuple[tuple[str, tuple[str, ...]], ...]]]:
    """The stimuli (id -> (speech, file)) and the order rows of a stimuli folder."""
    stimuli: dict[str, tuple[str, str]] = {}
    for rec in _read_csv(folder / "manifest.csv"):
        if not {"id", "file", "audio"} <= rec.keys():
            raise ConfigError("needs the columns id, file, audio", path=folder / "manifest.csv")
        stimuli[rec["id"]] = (rec["audio"], rec["file"])
    rows: dict[int, dict[int, list[tuple[int, str]]]] = {}
    order_path = folder / "order.csv"
    for rec in _read_csv(order_path):
        try:
            p, t, pos, sid = int(rec["participant"]), int(rec["trial"]), int(rec["position"]), rec["id"]
        except (KeyError, TypeError, ValueError):
            raise ConfigError(f"a row is not participant,trial,position,slot,id: {rec}", path=order_path) from None
        if sid not in stimuli:
            raise ConfigError(f"id {sid!r} is not in manifest.csv", path=order_path)
        rows.setdefault(p, {}).setdefault(t, []).append((pos, sid))
    if not rows:
        raise ConfigError("has no rows", path=order_path)
    order = {}
    for p, trials in rows.items():
        turns = []
        for t in sorted(trials):
            ids = tuple(sid for _, sid in sorted(trials[t]))
            speeches = {stimuli[sid][0] for sid in ids}
            if len(speeches) != 1:
                raise ConfigError(f"participant {p}'s trial {t} mixes speeches", path=order_path)
            turns.append((speeches.pop(), ids))
        order[p] = tuple(turns)
    return stimuli, order


@checks_arguments
def load_design(folder: str | os.PathLike) -> StudyDesign:
    """Read and validate ``design.json`` of a study folder.

    Parameters
    ----------
    folder : path
        A stimuli folder with ``design.json`` (``gesturekit study init``).

    Raises
    ------
    ConfigError
        Naming the file and the field: a missing or unknown field, a wrong type or value, a check
        or stimulus file that is not there.
    """
    folder = Path(folder)
    path = folder / "design.json"
    if not path.exists() and not path.is_symlink():
        raise ConfigError("is missing: write it with `gesturekit study init`", path=path)
    # a regular file of bounded size and nesting (a FIFO would hang the reader, deep nesting recurse)
    raw = read_json(path, error=ConfigError)
    r = Reader(path)
    top = (
        "format version seed secret title instructions rating pairwise attention audio_check checks questionnaire "
        "participants completion researcher"
    ).split()
    if not isinstance(raw, dict):
        raise r.fail("(top level)", f"must be an object, got {shown(raw)}")
    r.obj(raw, "", "", top)
    if raw["format"] != FORMAT:
        raise r.fail("format", f"must be {FORMAT!r}, got {shown(raw['format'])}")
    if raw["version"] != VERSION or isinstance(raw["version"], bool):
        raise r.fail("version", f"must be {VERSION}, got {shown(raw['version'])}")
    seed = r.integer(raw, "seed", "seed", 0)
    secret = raw["secret"]
    if not isinstance(secret, str) or not re.fullmatch(r"[0-9a-f]{32,128}", secret):
        raise r.fail("secret", "must be 32..128 random lowercase hex digits (`gesturekit study init` makes it)")
    title = r.text(raw, "title", "title", limit=200)
    instructions = r.text(raw, "instructions", "instructions")

    rating = r.obj(raw, "rating", "", ["enabled", "scale", "prompts"])
    rating_on = r.boolean(rating, "enabled", "rating.enabled")
    scale = r.choice(rating, "scale", "rating.scale", SCALES)
    prompts = []
    for i, pr in enumerate(r.array(rating, "prompts", "rating.prompts", min_items=1)):
        f = f"rating.prompts[{i}]"
        pr = r.obj({f: pr}, f, "", ["id", "text"])
        if not isinstance(pr.get("id"), str) or not ID_RE.fullmatch(pr["id"]):
            raise r.fail(f + ".id", f"must be a lowercase identifier (a-z, 0-9, _), got {shown(pr.get('id'))}")
        prompts.append((pr["id"], r.text(pr, "text", f + ".text", limit=500)))
    if len({p for p, _ in prompts}) != len(prompts):
        raise r.fail("rating.prompts", "must have unique ids")

    pw = r.obj(raw, "pairwise", "", ["enabled", "prompt", "pairs"])
    pairwise_on = r.boolean(pw, "enabled", "pairwise.enabled")
    pw_prompt = r.text(pw, "prompt", "pairwise.prompt", limit=500)
    pairs = pw["pairs"]
    if pairs == "all":
        pairs = None
    elif isinstance(pairs, bool) or not isinstance(pairs, int) or pairs < 1:
        raise r.fail("pairwise.pairs", f'must be "all" or a positive integer, got {shown(pairs)}')
    if not rating_on and not pairwise_on:
        raise r.fail("rating.enabled", "or pairwise.enabled must be true: a study needs rating or pairwise pages")

    att = r.obj(raw, "attention", "", ["per_participant", "kinds", "max_failures"])
    per_participant = r.integer(att, "per_participant", "attention.per_participant", 0)
    kinds = r.array(att, "kinds", "attention.kinds", min_items=1 if per_participant else 0)
    for i, k in enumerate(kinds):
        r.choice({"k": k}, "k", f"attention.kinds[{i}]", CHECK_KINDS)
    if len(set(kinds)) != len(kinds):
        raise r.fail("attention.kinds", f"must not repeat a kind, got {shown(kinds)}")
    if rating_on and "mismatched_audio" in kinds and "sync" not in {p for p, _ in prompts}:
        raise r.fail("attention.kinds", "mismatched_audio needs a rating prompt with the id 'sync'")
    max_failures = r.integer(att, "max_failures", "attention.max_failures", 0)

    stimuli, order = _folder_plan(folder)
    speeches = sorted({s for s, _ in stimuli.values()})
    if per_participant > len(speeches):
        raise r.fail(
            "attention.per_participant", f"must be at most the {len(speeches)} speeches, got {per_participant}"
        )

    ac = r.obj(raw, "audio_check", "", ["enabled", "id", "file", "beeps"], optional=["id", "file", "beeps"])
    audio_media, beeps = None, None
    if r.boolean(ac, "enabled", "audio_check.enabled"):
        aid = media_id(r, ac, "audio_check")
        audio_media = Media(aid, media_file(r, folder, ac, "audio_check", aid, ".wav"), "audio_check")
        beeps = r.integer(ac, "beeps", "audio_check.beeps", 1, 20)

    checks: dict[tuple[str, str], Media] = {}
    for i, c in enumerate(r.array(raw, "checks", "checks")):
        f = f"checks[{i}]"
        c = r.obj({f: c}, f, "", ["id", "kind", "speech", "file"])
        kind = r.choice(c, "kind", f + ".kind", CHECK_KINDS)
        speech = r.choice(c, "speech", f + ".speech", speeches)
        cid = media_id(r, c, f)
        if cid in stimuli or any(m.id == cid for m in checks.values()):
            raise r.fail(f + ".id", f"repeats the id of another media file: {cid}")
        checks[(speech, kind)] = Media(cid, media_file(r, folder, c, f, cid, ".mp4"), "check")
    missing = [(s, k) for s in speeches for k in kinds if (s, k) not in checks] if per_participant else []
    if missing:
        raise r.fail("checks", f"has no {missing[0][1]} video for the speech {missing[0][0]!r}")

    questions = []
    for i, q in enumerate(r.array(raw, "questionnaire", "questionnaire")):
        questions.append(question(r, q, f"questionnaire[{i}]"))
    if len({q["id"] for q in questions}) != len(questions):
        raise r.fail("questionnaire", "must have unique ids")

    participants = r.integer(raw, "participants", "participants", 1, len(order))
    if set(range(1, participants + 1)) - set(order):
        raise r.fail("participants", f"needs the rows 1..{participants} in order.csv")
    comp = r.obj(raw, "completion", "", ["code", "redirect"])
    code = r.text(comp, "code", "completion.code", limit=64)
    if not re.fullmatch(r"[A-Za-z0-9_-]+", code):
        raise r.fail("completion.code", f"must be letters, digits, - or _, got {shown(code)}")
    redirect = comp["redirect"]
    if redirect is not None and (not isinstance(redirect, str) or not re.fullmatch(r"https?://[^\s<>\"']+", redirect)):
        raise r.fail("completion.redirect", f"must be null or an http(s) URL, got {shown(redirect)}")
    res = r.obj(raw, "researcher", "", ["password_hash"])
    pw_hash = res["password_hash"]
    if pw_hash is not None and (not isinstance(pw_hash, str) or _parse_hash(pw_hash) is None):
        raise r.fail("researcher.password_hash", "must be null or a hash made by `gesturekit study init --password`")
    return StudyDesign(
        folder=folder,
        raw=raw,
        seed=seed,
        secret=secret,
        title=title,
        instructions=instructions,
        rating=rating_on,
        scale=scale,
        prompts=tuple(prompts),
        pairwise=pairwise_on,
        pairwise_prompt=pw_prompt,
        pairs=pairs,
        attention=per_participant,
        check_kinds=tuple(kinds),
        max_failures=max_failures,
        audio_check=audio_media,
        beeps=beeps,
        questionnaire=tuple(questions),
        participants=participants,
        completion_code=code,
        redirect=redirect,
        password_hash=pw_hash,
        order=order,
        stimuli=stimuli,
        checks=checks,
    )


# ---- the pages ----------------------------------------------------------------------------------


def _page_id(secret: str, row: int, index: int) -> str:
    key = f"gesturekit-pages:{secret}".encode()
    return hmac.new(key, f"{row}:{index}".encode(), hashlib.sha256).hexdigest()[:12]


def _expect(design: StudyDesign, kind: str) -> dict:
    """What a check page's answers must be for the rating scale: per prompt, or ``choice``."""
    if kind == "overlay":
        hi = _OVERLAY_MAX[design.scale]
        return {p: {"min": SCALE_RANGE[design.scale][0], "max": hi} for p, _ in design.prompts}
    return {"sync": {"min": SCALE_RANGE[design.scale][0], "max": _MISMATCH_MAX[design.scale]}}


@checks_arguments
def participant_pages(design: StudyDesign, row: int) -> list[Page]:
    """One participant's pages, in order: instructions, the audio check, a rating page per speech (in
    order.csv's order, its stimuli in their positions), pairwise pages, the questionnaire, done.

    Attention checks go into ``design.attention`` of the rating pages (one check video mixed in at a
    seeded position), or, without rating pages, come as extra pairwise pages (an overlay asking for
    LEFT beside a stimulus; a mismatched video beside the same speech's stimulus, to be judged worse).

    Parameters
    ----------
    design : StudyDesign
    row : int
        The participant's row of order.csv, 1-based (at most ``design.participants``).

    Returns
    -------
    list of Page
        The same for the same design and row.
    """
    if isinstance(row, bool) or not isinstance(row, (int, np.integer)) or not 1 <= row <= design.participants:
        raise ConfigError(f"row must be 1..{design.participants}, got {row!r}")
    row = int(row)
    rng = np.random.default_rng([design.seed, 0x57D2, row])
    folder = design.folder

    def stim(sid: str) -> Media:
        return Media(sid, folder / design.stimuli[sid][1], "stimulus")

    trials = design.order[row]
    specs: list[dict] = [{"kind": "instructions"}]
    if design.audio_check is not None:
        expect = {"count": {"min": design.beeps, "max": design.beeps}}
        check = {"media": design.audio_check.id, "kind": "audio_check", "expect": expect}
        specs.append({"kind": "audio_check", "media": (design.audio_check,), "check": check})
    rating = [{"kind": "rating", "media": tuple(map(stim, ids)), "speech": s} for s, ids in trials]
    pairwise = []
    for speech, ids in trials if design.pairwise else ():
        pairs = list(itertools.combinations(ids, 2))
        if design.pairs is not None and design.pairs < len(pairs):
            pairs = [pairs[i] for i in sorted(rng.choice(len(pairs), design.pairs, replace=False))]
        for k in rng.permutation(len(pairs)):
            left, right = pairs[k] if rng.integers(2) == 0 else pairs[k][::-1]
            pairwise.append({"kind": "pairwise", "media": (stim(left), stim(right)), "speech": speech})
    if design.attention:
        offset = int(rng.integers(len(design.check_kinds)))
        chosen = sorted(rng.choice(len(trials), design.attention, replace=False).tolist())
        for n, t in enumerate(chosen):
            kind = design.check_kinds[(n + offset) % len(design.check_kinds)]
            speech, ids = trials[t]
            media = design.checks[(speech, kind)]
            if design.rating:
                page = rating[t]
                at = int(rng.integers(len(page["media"]) + 1))
                page["media"] = page["media"][:at] + (media,) + page["media"][at:]
                page["check"] = {"media": media.id, "kind": kind, "expect": _expect(design, kind)}
                continue
            other = stim(ids[int(rng.integers(len(ids)))])
            left_check = kind == "overlay" or rng.integers(2) == 0
            pair = (media, other) if left_check else (other, media)
            # the overlay asks for LEFT; a mismatched video is the worse one of its pair
            choice = {"min": -2, "max": -1} if kind == "overlay" or not left_check else {"min": 1, "max": 2}
            page = {"kind": "pairwise", "media": pair, "speech": speech}
            page["check"] = {"media": media.id, "kind": kind, "expect": {"choice": choice}}
            at = int(rng.integers(len(pairwise) + 1))
            pairwise.insert(at, page)
    specs += rating if design.rating else []
    specs += pairwise
    if design.questionnaire:
        specs.append({"kind": "questionnaire"})
    specs.append({"kind": "done"})
    return [
        Page(
            id=_page_id(design.secret, row, i),
            index=i,
            kind=s["kind"],
            media=s.get("media", ()),
            check=s.get("check"),
            speech=s.get("speech"),
        )
        for i, s in enumerate(specs)
    ]


@checks_arguments
def media_index(design: StudyDesign) -> dict[str, Media]:
    """Every media file the study may serve, by id: the stimuli, the check videos, the beeps."""
    out = {sid: Media(sid, design.folder / f, "stimulus") for sid, (_, f) in design.stimuli.items()}
    out.update({m.id: m for m in design.checks.values()})
    if design.audio_check is not None:
        out[design.audio_check.id] = design.audio_check
    return out


@checks_arguments
def check_answer(page: Page, answers: Mapping[str, Any]) -> bool | None:
    """Whether a page's answers pass its check; None when the page holds no check.

    Parameters
    ----------
    page : Page
    answers : dict
        As posted: rating ``{media id: {prompt: value}}``; pairwise ``{"choice": -2..2}``;
        audio check ``{"count": n}``. A missing or non-numeric answer fails.
    """
    if page.check is None:
        return None
    target: Any = answers.get(page.check["media"]) if page.kind == "rating" else answers
    if not isinstance(target, Mapping):
        return False
    for key, span in page.check["expect"].items():
        value = target.get(key)
        if not finite(value) or not span["min"] <= value <= span["max"]:
            return False
    return True


# ---- the researcher's password ------------------------------------------------------------------


@checks_arguments
def hash_password(password: str, *, salt: bytes | None = None) -> str:
    """A salted scrypt hash of ``password``: ``scrypt$N$r$p$SALT$HASH`` (hex), for design.json.

    Parameters
    ----------
    password : str
        At least 8 characters.
    salt : bytes, optional
        16 random bytes by default.
    """
    if not isinstance(password, str) or len(password) < 8:
        raise ConfigError("the researcher's password needs at least 8 characters")
    salt = secrets.token_bytes(16) if salt is None else salt
    digest = hashlib.scrypt(password.encode(), salt=salt, **_SCRYPT, dklen=32)
    return f"scrypt${_SCRYPT['n']}${_SCRYPT['r']}${_SCRYPT['p']}${salt.hex()}${digest.hex()}"


def _parse_hash(stored: str) -> tuple[int, int, int, bytes, bytes] | None:
    m = re.fullmatch(r"scrypt\$(\d{1,7})\$(\d{1,2})\$(\d{1,2})\$([0-9a-f]{16,128})\$([0-9a-f]{64})", stored)
    if m is None:
        return None
    n, r, p = int(m[1]), int(m[2]), int(m[3])
    if n < 2 or n & (n - 1) or n > 2**20 or not 1 <= r <= 16 or not 1 <= p <= 16:
        return None
    return n, r, p, bytes.fromhex(m[4]), bytes.fromhex(m[5])


@checks_arguments
def verify_password(password: str, stored: str | None) -> bool:
    """Whether ``password`` matches a :func:`hash_password` hash (constant-time compare); False for none."""
    parsed = None if stored is None else _parse_hash(stored)
    if parsed is None or not isinstance(password, str):
        return False
    n, r, p, salt, digest = parsed
    got = hashlib.scrypt(password.encode(), salt=salt, n=n, r=r, p=p, dklen=len(digest), maxmem=2**27)
    return hmac.compare_digest(got, digest)


# ---- writing a design ---------------------------------------------------------------------------


@checks_arguments
def init_study(
    folder: str | os.PathLike,
    *,
    scale: str = "likert7",
    rating: bool = True,
    pairwise: bool = False,
    attention: int = 2,
    kinds: Sequence[str] = CHECK_KINDS,
    audio_check: bool = True,
    password: str | None = None,
    redirect: str | None = None,
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
    secret: str | None = None,
) -> StudyDesign:
    """Add a design to a stimuli folder: ``design.json`` and the check media in ``checks/``.

    Parameters
    ----------
    folder : path
        A complete stimuli folder (``gesturekit stimuli``).
    scale : str
        ``"likert7"`` (the paper's seven points) or ``"slider100"`` (HEMVIP's 0..100).
    rating, pairwise : bool
        Rating pages (every stimulus of a speech on one page) and/or pairwise pages (all pairs).
    attention : int
        Attention checks per participant (at most the speeches).
    kinds : sequence of str
        Of :data:`CHECK_KINDS`; mismatched_audio needs two speeches.
    audio_check : bool
        Begin with a count-the-beeps page.
    password : str, optional
        The researcher's password (stored as a scrypt hash).
    redirect : str, optional
        Where a participant goes when done; ``{code}`` in it becomes the completion code.
    overwrite : bool
        Replace an existing design.json (and its check media).
    progress : callable(done, total), optional
        Frames of check video written.
    secret : str, optional
        The key of the page ids and the completion code (hex); 32 random bytes by default.

    Returns
    -------
    StudyDesign
        As :func:`load_design` reads it back. The same folder, options and secret give the same file
        and check media (but for the password's random salt).
    """
    from .media import make_audio_check, make_check_videos

    folder = Path(folder)
    study_path, path = folder / "study.json", folder / "design.json"
    try:
        study = json.loads(study_path.read_text(encoding="utf-8"))
    except (FileNotFoundError, json.JSONDecodeError, UnicodeDecodeError):
        msg = "is missing or unreadable: make the stimuli first (`gesturekit stimuli`)"
        raise ConfigError(msg, path=study_path) from None
    if not isinstance(study, dict) or study.get("format") != "gesturekit-study" or study.get("complete") is False:
        raise ConfigError("is not a complete gesturekit study (the stimuli run did not finish)", path=study_path)
    if path.exists() and not overwrite:
        raise OutputError("exists; pass --force (overwrite=True) to replace the design", path=path)
    if scale not in SCALES:
        raise ConfigError(f"scale must be one of {', '.join(SCALES)}, got {scale!r}")
    bad = [k for k in kinds if k not in CHECK_KINDS]
    if bad or (attention and not kinds):
        raise ConfigError(f"attention check kinds must be of {', '.join(CHECK_KINDS)}, got {list(kinds)}")
    seed = int(study.get("seed", 0))
    stimuli, order = _folder_plan(folder)
    speeches = sorted({s for s, _ in stimuli.values()})
    if attention and "mismatched_audio" in kinds and len(speeches) < 2:
        raise ConfigError("a mismatched_audio check needs two speeches; use --attention 0 or more speeches")
    if not 0 <= attention <= len(speeches):
        raise ConfigError(f"attention checks per participant must be 0..{len(speeches)} (one per speech at most)")
    secret = secrets.token_hex(32) if secret is None else secret
    if not isinstance(secret, str) or not re.fullmatch(r"[0-9a-f]{32,128}", secret):
        raise ConfigError("the secret must be 32..128 lowercase hex digits")
    code = hmac.new(f"gesturekit-completion:{secret}".encode(), b"code", hashlib.sha256).hexdigest()[:10].upper()
    if redirect is not None:
        redirect = redirect.replace("{code}", code)
    checks = []
    if attention:
        checks = make_check_videos(
            folder, seed=seed, stimuli=stimuli, kinds=tuple(kinds), pairwise=not rating, progress=progress
        )
    audio = {"enabled": False}
    if audio_check:
        audio = {"enabled": True, **make_audio_check(folder, seed=seed)}
    # check media of an earlier design that this one does not use (another seed, kinds, or none)
    keep = {c["file"] for c in checks} | ({audio["file"]} if audio_check else set())
    for f in sorted((folder / "checks").glob("*")) if (folder / "checks").is_dir() else ():
        if re.fullmatch(r"[0-9a-f]{8,64}\.(mp4|wav)", f.name) and f"checks/{f.name}" not in keep:
            f.unlink()
    animations = max(len(ids) for turns in order.values() for _, ids in turns)
    design = {
        "format": FORMAT,
        "version": VERSION,
        "seed": seed,
        "secret": secret,
        "title": "Rating virtual character gestures",
        "instructions": default_instructions(animations, scale, checks=bool(rating) and attention > 0),
        "rating": {"enabled": bool(rating), "scale": scale, "prompts": [dict(p) for p in DEFAULT_PROMPTS]},
        "pairwise": {
            "enabled": bool(pairwise),
            "prompt": "Which character's gestures fit the speech better?",
            "pairs": "all",
        },
        "attention": {"per_participant": int(attention), "kinds": list(kinds), "max_failures": 1},
        "audio_check": audio,
        "checks": checks,
        "questionnaire": [dict(q) for q in DEFAULT_QUESTIONNAIRE],
        "participants": len(order),
        "completion": {"code": code, "redirect": redirect},
        "researcher": {"password_hash": None if password is None else hash_password(password)},
    }
    data = (json.dumps(design, indent=1, ensure_ascii=False) + "\n").encode()
    atomic_write(path, lambda f: f.write(data), overwrite=True)
    return load_design(folder)
