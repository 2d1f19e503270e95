"""A study's design: design.json validated field by field, participant pages, the check media, checks."""

import copy
import dataclasses
import hashlib
import itertools
import json
import re
import shutil
import subprocess
from collections import Counter

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.cli import main
from gesturekit.errors import ConfigError, OutputError
from gesturekit.export.video import ffmpeg_executable, probe_media
from gesturekit.study import (
    Page,
    check_answer,
    hash_password,
    init_study,
    load_design,
    media_index,
    participant_pages,
    verify_password,
)
from gesturekit.study.media import OVERLAY_TEXT, beep_samples, draw_overlay, overlay_box
from tests.study_helpers import STUDY_SYSTEMS, tiny_study  # noqa: F401

pytestmark = pytest.mark.slow  # tiny_study builds a demo database and makes a stimuli folder once per module

SECRET = "5ec7e7" * 8


@pytest.fixture(scope="module")
def study(tiny_study, tmp_path_factory):  # noqa: F811
    folder = tmp_path_factory.mktemp("design") / "study"
    shutil.copytree(tiny_study, folder)
    design = init_study(folder, pairwise=True, secret=SECRET)
    return design


@pytest.fixture(scope="module")
def pairwise_study(tiny_study, tmp_path_factory):  # noqa: F811
    folder = tmp_path_factory.mktemp("pairwise") / "study"
    shutil.copytree(tiny_study, folder)
    return init_study(folder, rating=False, pairwise=True, scale="slider100", redirect="https://x.org/done?cc={code}")


# ---- validation ---------------------------------------------------------------------------------

# (field path, a bad value, the field the error must name)
MUTATIONS = [
    ("format", "gesturekit-study", "format"),
    ("version", 2, "version"),
    ("version", True, "version"),
    ("seed", -1, "seed"),
    ("seed", 1.5, "seed"),
    ("seed", "0", "seed"),
    ("secret", "0", "secret"),
    ("secret", "XYZ" * 20, "secret"),
    ("secret", None, "secret"),
    ("title", "", "title"),
    ("title", "x" * 300, "title"),
    ("title", 5, "title"),
    ("instructions", None, "instructions"),
    ("instructions", "  ", "instructions"),
    ("rating", [], "rating"),
    ("rating.enabled", "yes", "rating.enabled"),
    ("rating.enabled", 1, "rating.enabled"),
    ("rating.scale", "likert5", "rating.scale"),
    ("rating.scale", 7, "rating.scale"),
    ("rating.prompts", [], "rating.prompts"),
    ("rating.prompts", "natural", "rating.prompts"),
    ("rating.prompts[0]", "natural", "rating.prompts[0]"),
    ("rating.prompts[0].id", "Natural", "rating.prompts[0].id"),
    ("rating.prompts[0].id", 3, "rating.prompts[0].id"),
    ("rating.prompts[0].id", "sync", "rating.prompts"),
    ("rating.prompts[1].id", "synchrony", "attention.kinds"),
    ("rating.prompts[0].text", "", "rating.prompts[0].text"),
    ("pairwise", None, "pairwise"),
    ("pairwise.enabled", "no", "pairwise.enabled"),
    ("pairwise.prompt", "", "pairwise.prompt"),
    ("pairwise.pairs", 0, "pairwise.pairs"),
    ("pairwise.pairs", "some", "pairwise.pairs"),
    ("pairwise.pairs", True, "pairwise.pairs"),
    ("attention.per_participant", -1, "attention.per_participant"),
    ("attention.per_participant", 3, "attention.per_participant"),
    ("attention.per_participant", "2", "attention.per_participant"),
    ("attention.kinds", "overlay", "attention.kinds"),
    ("attention.kinds", ["overlay", "overlay"], "attention.kinds"),
    ("attention.kinds", ["nonsense"], "attention.kinds[0]"),
    ("attention.kinds", [], "attention.kinds"),
    ("attention.max_failures", -1, "attention.max_failures"),
    ("attention.max_failures", None, "attention.max_failures"),
    ("audio_check.enabled", "true", "audio_check.enabled"),
    ("audio_check.id", "XYZ", "audio_check.id"),
    ("audio_check.file", "../../etc/passwd", "audio_check.file"),
    ("audio_check.beeps", 0, "audio_check.beeps"),
    ("audio_check.beeps", "5", "audio_check.beeps"),
    ("checks", "x", "checks"),
    ("checks[0].kind", "other", "checks[0].kind"),
    ("checks[0].speech", "nope.wav", "checks[0].speech"),
    ("checks[0].id", "zz", "checks[0].id"),
    ("checks[0].file", "videos/x.mp4", "checks[0].file"),
    ("questionnaire", {}, "questionnaire"),
    ("questionnaire[0].type", "date", "questionnaire[0].type"),
    ("questionnaire[0].id", "Age", "questionnaire[0].id"),
    ("questionnaire[0].min", "a", "questionnaire[0].min"),
    ("questionnaire[0].min", 1000, "questionnaire[0].min"),
    ("questionnaire[0].text", "", "questionnaire[0].text"),
    ("questionnaire[1].options", ["a", "b"], "questionnaire[1].options"),
    ("participants", 0, "participants"),
    ("participants", 7, "participants"),
    ("participants", "6", "participants"),
    ("completion.code", "", "completion.code"),
    ("completion.code", "a b", "completion.code"),
    ("completion.redirect", "javascript:alert(1)", "completion.redirect"),
    ("completion.redirect", 5, "completion.redirect"),
    ("researcher.password_hash", "plaintext", "researcher.password_hash"),
    ("researcher.password_hash", 5, "researcher.password_hash"),
]


def _set(raw, path, value):
    keys = [int(k) if k.isdigit() else k for k in re.findall(r"[^.\[\]]+", path)]
    node = raw
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value


def _paths(raw, prefix=""):
    """Every field path of a JSON object (objects and list items included)."""
    for k, v in raw.items():
        path = f"{prefix}{k}"
        yield path
        if isinstance(v, dict):
            yield from _paths(v, path + ".")
        elif isinstance(v, list):
            for i, item in enumerate(v):
                if isinstance(item, dict):
                    yield from _paths(item, f"{path}[{i}].")


def _expect_error(folder, raw, field):
    (folder / "design.json").write_text(json.dumps(raw))
    with pytest.raises(ConfigError) as err:
        load_design(folder)
    assert "design.json" in str(err.value) and f"'{field}" in str(err.value), str(err.value)


@settings(
    max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(st.sampled_from(MUTATIONS), st.data())
def test_every_bad_field_is_named_with_the_file(study, mutation, data):
    good = json.loads((study.folder / "design.json").read_text())
    raw = copy.deepcopy(good)
    path, value, field = mutation
    _set(raw, path, value)
    try:
        _expect_error(study.folder, raw, field)
        # a missing field, or one that is not known, is named too
        raw = copy.deepcopy(good)
        missing = data.draw(st.sampled_from(sorted(set(_paths(good)) - {"questionnaire[1].optional"})))
        parent_path, _, key = missing.rpartition(".")
        parent = raw
        for k in [int(k) if k.isdigit() else k for k in re.findall(r"[^.\[\]]+", parent_path)]:
            parent = parent[k]
        optional = {"min", "max", "optional", "options"}  # of questions; their absence is allowed
        if key not in optional and parent_path != "audio_check":
            del parent[key]
            _expect_error(study.folder, raw, missing)
        raw = copy.deepcopy(good)
        parent = raw
        for k in [int(k) if k.isdigit() else k for k in re.findall(r"[^.\[\]]+", parent_path)]:
            parent = parent[k]
        parent["surplus"] = 1
        _expect_error(study.folder, raw, (parent_path + "." if parent_path else "") + "surplus")
    finally:
        (study.folder / "design.json").write_text(json.dumps(good, indent=1) + "\n")
    assert load_design(study.folder).raw == good


def test_no_pages_at_all_and_bad_json_are_refused(study):
    good = (study.folder / "design.json").read_text()
    try:
        raw = json.loads(good)
        raw["rating"]["enabled"] = raw["pairwise"]["enabled"] = False
        _expect_error(study.folder, raw, "rating.enabled")
        (study.folder / "design.json").write_text("{not json")
        with pytest.raises(ConfigError, match="design.json: not valid JSON"):
            load_design(study.folder)
        (study.folder / "design.json").write_text("[]")
        with pytest.raises(ConfigError, match="must be an object"):
            load_design(study.folder)
    finally:
        (study.folder / "design.json").write_text(good)


def test_init_refuses_to_overwrite_and_is_deterministic(study, tiny_study, tmp_path):  # noqa: F811
    with pytest.raises(OutputError, match="design.json: exists"):
        init_study(study.folder)
    other = tmp_path / "study"
    shutil.copytree(tiny_study, other)
    init_study(other, pairwise=True, secret=SECRET)
    assert (other / "design.json").read_bytes() == (study.folder / "design.json").read_bytes()
    # by default a random secret: page ids and the completion code nobody can work out from the seed
    third = tmp_path / "third"
    shutil.copytree(tiny_study, third)
    fresh = init_study(third, pairwise=True)
    assert fresh.secret != SECRET and fresh.completion_code != study.completion_code
    assert {p.id for p in participant_pages(fresh, 1)}.isdisjoint(p.id for p in participant_pages(study, 1))
    layout = [[(m.id, m.kind) for m in p.media] for p in participant_pages(study, 1)]
    assert [[(m.id, m.kind) for m in p.media] for p in participant_pages(fresh, 1)] == layout
    for f in sorted((study.folder / "checks").iterdir()):
        assert (
            hashlib.sha256(f.read_bytes()).digest() == hashlib.sha256((other / "checks" / f.name).read_bytes()).digest()
        )
    with pytest.raises(ConfigError, match="study.json"):
        init_study(tmp_path)


def test_init_command(tiny_study, tmp_path, capsys):  # noqa: F811
    folder = tmp_path / "study"
    shutil.copytree(tiny_study, folder)
    args = ["study", "init", str(folder), "--scale", "slider100", "--attention", "1", "--password", "correct horse"]
    assert main(args) == 0
    assert "completion code" in capsys.readouterr().out
    design = load_design(folder)
    assert design.scale == "slider100" and design.attention == 1 and not design.pairwise
    assert verify_password("correct horse", design.password_hash)
    assert main(args) == 2  # exists
    assert "--force" in capsys.readouterr().err
    assert main(["study", "init", str(folder), "--no-rating", "--force"]) == 2
    # replaced by a design without checks: the earlier check media go
    assert main(["study", "init", str(folder), "--attention", "0", "--no-audio-check", "--force"]) == 0
    assert not list((folder / "checks").iterdir())
    assert participant_pages(load_design(folder), 1)[1].kind == "rating"


def test_password_hash():
    h = hash_password("s3cret-pass")
    assert h.startswith("scrypt$") and "s3cret" not in h
    assert verify_password("s3cret-pass", h)
    assert not verify_password("s3cret-pasS", h)
    assert not verify_password("s3cret-pass", None)
    assert not verify_password("s3cret-pass", "scrypt$3$8$1$00$00")
    assert hash_password("s3cret-pass") != h  # salted
    with pytest.raises(ConfigError, match="8 characters"):
        hash_password("short")


# ---- pages --------------------------------------------------------------------------------------


def _order(folder):
    return pd.read_csv(folder / "order.csv")


def test_pages_are_deterministic_and_show_every_stimulus_once_in_order(study):
    order = _order(study.folder)
    index = media_index(study)
    seen_ids = set()
    for row in range(1, study.participants + 1):
        pages = participant_pages(study, row)
        assert pages == participant_pages(study, row)
        assert [p.index for p in pages] == list(range(len(pages)))
        assert [p.kind for p in pages][:2] == ["instructions", "audio_check"]
        assert [p.kind for p in pages][-2:] == ["questionnaire", "done"]
        ids = [p.id for p in pages]
        assert all(re.fullmatch(r"[0-9a-f]{12}", i) for i in ids) and not seen_ids & set(ids)
        seen_ids |= set(ids)
        mine = order[order["participant"] == row].sort_values(["trial", "position"])
        rating = [p for p in pages if p.kind == "rating"]
        shown = [m.id for p in rating for m in p.media if m.kind == "stimulus"]
        assert shown == mine["id"].tolist()  # every stimulus once, in order.csv's order
        checks = [p.check for p in pages if p.kind == "rating" and p.check]
        assert len(checks) == study.attention == 2
        assert Counter(c["kind"] for c in checks) == Counter(study.check_kinds)
        for p in rating:
            assert sum(m.kind == "check" for m in p.media) == (p.check is not None)
        pairs = [p for p in pages if p.kind == "pairwise"]
        for trial, group in mine.groupby("trial"):
            want = {frozenset(c) for c in itertools.combinations(group["id"], 2)}
            got = [frozenset(m.id for m in p.media) for p in pairs if p.speech == rating[trial - 1].speech]
            assert len(got) == len(want) and set(got) == want
        for p in pages:
            for m in p.media:
                assert index[m.id] == m and m.path.is_file()
    with pytest.raises(ConfigError):
        participant_pages(study, study.participants + 1)


def test_pairwise_only_pages_carry_the_checks(pairwise_study):
    d = pairwise_study
    assert d.redirect == f"https://x.org/done?cc={d.completion_code}"
    for row in range(1, d.participants + 1):
        pages = participant_pages(d, row)
        assert not [p for p in pages if p.kind == "rating"]
        checks = [p for p in pages if p.check and p.kind == "pairwise"]
        assert len(checks) == 2
        for p in checks:
            check = next(m for m in p.media if m.kind == "check")
            other = next(m for m in p.media if m.kind == "stimulus")
            assert d.stimuli[other.id][0] == p.speech
            left_is_check = p.media[0] == check
            if p.check["kind"] == "overlay":
                assert left_is_check and p.check["expect"] == {"choice": {"min": -2, "max": -1}}
            # the overlay asks for LEFT; the mismatched video is to be judged the worse one
            good = -2 if p.check["kind"] == "overlay" or not left_is_check else 2
            assert check_answer(p, {"choice": good}) is True
            assert check_answer(p, {"choice": -good}) is False
            assert check_answer(p, {"choice": 0}) is False


# ---- check media --------------------------------------------------------------------------------


def _ffmpeg_header(path):
    text = subprocess.run([ffmpeg_executable(), "-hide_banner", "-i", str(path)], capture_output=True, text=True).stderr
    return text


def _metadata(header):
    """The key: value lines of ``ffmpeg -i``'s output, less what differs between any two files."""
    keep = []
    for line in header.splitlines():
        m = re.match(r"\s+(\w+)\s*: (.*)", line)
        if m and m[1] not in ("Duration",):
            keep.append((m[1], m[2]))
    return sorted(keep)


def _decode_audio(path):
    raw = subprocess.run(
        [
            ffmpeg_executable(),
            "-nostdin",
            "-loglevel",
            "error",
            "-i",
            str(path),
            "-f",
            "f32le",
            "-ac",
            "1",
            "-ar",
            "16000",
            "-",
        ],
        capture_output=True,
        check=True,
    ).stdout
    return np.frombuffer(raw, "<f4")


def _frames(path, n=None):
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    w, h = next(reader)["size"]
    frames = [np.frombuffer(f, np.uint8).reshape(h, w, 3).astype(np.int16) for f in reader]
    return np.stack(frames[:n])


def test_check_media_look_like_the_stimuli(study):
    manifest = pd.read_csv(study.folder / "manifest.csv")
    stim = {r.id: r for r in manifest.itertuples()}
    systems = set(STUDY_SYSTEMS)
    some_stimulus = study.folder / manifest["file"][0]
    reference = probe_media(some_stimulus)
    ref_meta = _metadata(_ffmpeg_header(some_stimulus))
    assert len(study.checks) == 4
    for (speech, _kind), media in study.checks.items():
        assert re.fullmatch(r"[0-9a-f]{10}\.mp4", media.path.name)  # named like a stimulus
        assert len(media.id) == len(manifest["id"][0])
        info = probe_media(media.path)
        same_speech = manifest[manifest["audio"] == speech]
        host = probe_media(study.folder / same_speech["file"].iloc[0])
        for key in ("codec", "pix_fmt", "width", "height", "fps", "frames"):
            assert info["video"][key] == host["video"][key] == reference["video"][key] or key == "frames"
        assert info["video"]["frames"] == host["video"]["frames"]
        assert info["audio"]["codec"] == host["audio"]["codec"]
        assert info["audio"]["sample_rate"] == host["audio"]["sample_rate"]
        assert info["audio"]["duration"] == pytest.approx(host["audio"]["duration"], abs=0.03)
        header = _ffmpeg_header(media.path)
        assert _metadata(header) == ref_meta  # container tags, brands, encoder, handler names, bitexact
        assert not any(s in header for s in systems) and not any(s in media.path.name for s in systems)
    # the beeps: a WAV under an opaque name with the design's number of tones
    wav = study.audio_check.path
    assert re.fullmatch(r"[0-9a-f]{10}\.wav", wav.name)
    samples = _decode_audio(wav)
    frames = np.abs(samples[: len(samples) // 320 * 320]).reshape(-1, 320).max(axis=1)  # 20 ms envelope
    loud = frames > 0.1
    assert int((loud[1:] & ~loud[:-1]).sum()) == study.beeps and 3 <= study.beeps <= 7
    assert len(beep_samples(study.beeps)) / 48000 == pytest.approx(len(samples) / 16000, abs=0.01)
    assert stim  # the manifest was read


def test_overlay_shows_its_text_in_the_box(study):
    manifest = pd.read_csv(study.folder / "manifest.csv")
    for (speech, kind), media in study.checks.items():
        if kind != "overlay":
            continue
        check = _frames(media.path, 8)
        h, w = check.shape[1:3]
        x0, y0, x1, y1 = overlay_box(w, h)
        inside = np.zeros((h, w), bool)
        inside[y0:y1, x0:x1] = True
        best = None
        for f in manifest[manifest["audio"] == speech]["file"]:
            src = _frames(study.folder / f, 8)
            outside = np.abs(check - src)[:, ~inside].mean()
            if best is None or outside < best[0]:
                best = (outside, np.abs(check - src)[:, inside].mean(), src)
        outside, inside_diff, src = best
        assert outside < 3.0  # the stimulus it was made from, re-encoded
        assert inside_diff > 30.0  # a dark band with white text
        band = check[:, y0:y1, x0:x1]
        assert (band > 150).all(axis=-1).mean() > 0.003  # light letters
        assert (band < 60).all(axis=-1).mean() > 0.5  # on a dark band
    assert OVERLAY_TEXT["rating"].startswith("Please rate this clip 1")


def test_mismatched_audio_is_the_page_speech_under_another_speech_motion(study):
    manifest = pd.read_csv(study.folder / "manifest.csv")
    for (speech, kind), media in study.checks.items():
        if kind != "mismatched_audio":
            continue
        sound = _decode_audio(media.path)
        for f, a in zip(manifest["file"], manifest["audio"]):
            ref = _decode_audio(study.folder / f)
            n = min(len(ref), len(sound))
            r = np.corrcoef(sound[:n], ref[:n])[0, 1]
            assert (r > 0.95) if a == speech else (r < 0.5), (a, speech, r)
        frames = _frames(media.path)
        n = len(frames)
        diff = {
            a: min(np.abs(frames[:n] - _frames(study.folder / f)[:n]).mean() for f in g["file"])
            for a, g in manifest.groupby("audio")
        }
        other = next(a for a in diff if a != speech)
        assert diff[other] < 3.0 < diff[speech]  # the motion of the other speech


# ---- check answers ------------------------------------------------------------------------------


def test_check_answers(study):
    pages = participant_pages(study, 1)
    assert check_answer(pages[0], {}) is None
    audio = pages[1]
    assert check_answer(audio, {"count": study.beeps}) is True
    assert check_answer(audio, {"count": study.beeps + 1}) is False
    assert check_answer(audio, {"count": str(study.beeps)}) is False
    plain = next(p for p in pages if p.kind == "rating" and p.check is None) if study.attention < 2 else None
    assert plain is None or check_answer(plain, {}) is None
    assert check_answer(next(p for p in pages if p.kind == "pairwise"), {"choice": 1}) is None
    for scale, (overlay_ok, overlay_bad, sync_ok, sync_bad) in {
        "likert7": (1, 2, 3, 4),
        "slider100": (10, 11, 30, 31),
    }.items():
        design = dataclasses.replace(study, scale=scale)
        for page in participant_pages(design, 1):
            if page.kind != "rating" or page.check is None:
                continue
            cid = page.check["media"]

            def answers(natural, sync, cid=cid, page=page):
                out = {m.id: {"natural": 5, "sync": 5} for m in page.media}
                out[cid] = {"natural": natural, "sync": sync}
                return out

            if page.check["kind"] == "overlay":
                assert check_answer(page, answers(overlay_ok, overlay_ok)) is True
                assert check_answer(page, answers(overlay_ok, overlay_bad)) is False
                assert check_answer(page, answers(overlay_bad, overlay_ok)) is False
            else:
                assert check_answer(page, answers(7 if scale == "likert7" else 100, sync_ok)) is True
                assert check_answer(page, answers(1, sync_bad)) is False
            assert check_answer(page, answers(True, True)) is False  # not a number
            assert check_answer(page, {}) is False
            assert check_answer(page, {cid: "1"}) is False
    fake = Page(id="0" * 12, index=3, kind="rating", media=(), check=None)
    assert check_answer(fake, {"x": {"natural": 1}}) is None


@settings(max_examples=25, deadline=None)
@given(st.integers(40, 960), st.integers(40, 720), st.sampled_from(sorted(OVERLAY_TEXT.values())))
def test_overlay_text_stays_in_its_box_at_any_size(width, height, text):
    frame = np.full((height, width, 3), 120, np.uint8)
    out = draw_overlay(frame, text)
    x0, y0, x1, y1 = overlay_box(width, height)
    changed = (out != frame).any(axis=-1)
    inside = np.zeros_like(changed)
    inside[y0:y1, x0:x1] = True
    assert not changed[~inside].any()  # the rest of the frame as it was
    assert (out[y0:y1, x0:x1] > 150).all(axis=-1).any()  # light letters on the dark band
