"""Field-by-field reading of design.json: every error names the file and the field."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import ConfigError

QUESTION_TYPES = ("number", "text", "choice")
ID_RE = re.compile(r"[a-z][a-z0-9_]{0,31}")
_HEX_RE = re.compile(r"[0-9a-f]{8,64}")


class Reader:
    """Field access on design.json's dict with errors that name the file and the field."""

    def __init__(self, path: Path):
        self.path = path

    def fail(self, field: str, problem: str) -> ConfigError:
        return ConfigError(f"field {field!r} {problem}", path=self.path)

    def obj(self, parent: Mapping, key: str, prefix: str, keys: Sequence[str], optional: Sequence[str] = ()) -> dict:
        field = prefix + key
        value = parent.get(key) if key else parent
        if not isinstance(value, dict):
            raise self.fail(field or "(top level)", f"must be an object, got {shown(value)}")
        for k in keys:
            if k not in value and k not in optional:
                raise self.fail(f"{field}.{k}" if field else k, "is missing")
        for k in value:
            if k not in keys:
                raise self.fail(f"{field}.{k}" if field else k, "is not a known field")
        return value

    def boolean(self, parent: Mapping, key: str, field: str) -> bool:
        value = parent.get(key)
        if not isinstance(value, bool):
            raise self.fail(field, f"must be true or false, got {shown(value)}")
        return value

    def text(self, parent: Mapping, key: str, field: str, *, limit: int = 20000, empty: bool = False) -> str:
        value = parent.get(key)
        if not isinstance(value, str) or (not empty and not value.strip()) or len(value) > limit:
            raise self.fail(field, f"must be a non-empty text of at most {limit} characters, got {shown(value)}")
        return value

    def integer(self, parent: Mapping, key: str, field: str, lo: int, hi: int | None = None) -> int:
        value = parent.get(key)
        if isinstance(value, bool) or not isinstance(value, int) or value < lo or (hi is not None and value > hi):
            span = f"{lo}..{hi}" if hi is not None else f">= {lo}"
            raise self.fail(field, f"must be an integer {span}, got {shown(value)}")
        return value

    def choice(self, parent: Mapping, key: str, field: str, options: Sequence[str]) -> str:
        value = parent.get(key)
        if value not in options or not isinstance(value, str):
            raise self.fail(field, f"must be one of {', '.join(options)}, got {shown(value)}")
        return value

    def array(self, parent: Mapping, key: str, field: str, *, min_items: int = 0) -> list:
        value = parent.get(key)
        if not isinstance(value, list) or len(value) < min_items:
            raise self.fail(field, f"must be a list of at least {min_items} items, got {shown(value)}")
        return value


def shown(value: Any) -> str:
    text = json.dumps(value) if isinstance(value, (dict, list, str, int, float, bool, type(None))) else repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def media_id(r: Reader, obj: Mapping, field: str) -> str:
    value = obj.get("id")
    if not isinstance(value, str) or not _HEX_RE.fullmatch(value):
        raise r.fail(field + ".id", f"must be 8..64 lowercase hex digits, got {shown(value)}")
    return value


def media_file(r: Reader, folder: Path, obj: Mapping, field: str, mid: str, suffix: str) -> Path:
    if obj.get("file") != f"checks/{mid}{suffix}":
        raise r.fail(field + ".file", f"must be 'checks/{mid}{suffix}', got {shown(obj.get('file'))}")
    path = folder / "checks" / f"{mid}{suffix}"
    if not path.is_file():
        raise r.fail(field + ".file", f"names a file that is not there ({path}); run `gesturekit study init --force`")
    return path


def question(r: Reader, q: Any, f: str) -> dict:
    keys = ["id", "text", "type", "min", "max", "options", "optional"]
    q = r.obj({f: q}, f, "", keys, optional=["min", "max", "options", "optional"])
    if not isinstance(q.get("id"), str) or not ID_RE.fullmatch(q["id"]):
        raise r.fail(f + ".id", f"must be a lowercase identifier (a-z, 0-9, _), got {shown(q.get('id'))}")
    r.text(q, "text", f + ".text", limit=500)
    kind = r.choice(q, "type", f + ".type", QUESTION_TYPES)
    if "optional" in q:
        r.boolean(q, "optional", f + ".optional")
    for bound in ("min", "max"):
        if bound in q and (kind != "number" or not finite(q[bound])):
            raise r.fail(f"{f}.{bound}", f"must be a finite number on a number question, got {shown(q[bound])}")
    if kind == "number" and q.get("min", -math.inf) > q.get("max", math.inf):
        raise r.fail(f + ".min", f"must not exceed max, got {q['min']} > {q['max']}")
    if kind == "choice":
        options = r.array(q, "options", f + ".options", min_items=2)
        if not all(isinstance(o, str) and o.strip() for o in options) or len(set(options)) != len(options):
            raise r.fail(f + ".options", "must be distinct non-empty texts")
    elif "options" in q:
        raise r.fail(f + ".options", "belongs to choice questions only")
    return q


def finite(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
