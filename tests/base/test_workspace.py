"""gesturekit.workspace: the databases and speech files a user's folders hold (shared by the CLI and the app)."""

from __future__ import annotations

import tempfile
from pathlib import Path
from types import SimpleNamespace

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.datasets.positions import load_position_joint_map
from gesturekit.datasets.presets import PRESETS
from gesturekit.datasets.takes import AUDIO_EXTENSIONS, TakeSource, discover_takes, iter_takes
from gesturekit.errors import ConfigError, InputFileError, OutputError
from gesturekit.workspace import (
    DEMO_DATABASE_LABEL,
    build_database,
    database_folders,
    expand_speech,
    is_generated,
    open_database,
    speech_files,
)
from tests.cli.test_cli import _positions_folder

_SUFFIXES = (
    [e.upper() if i % 2 else e for i, e in enumerate(AUDIO_EXTENSIONS)]
    + list(AUDIO_EXTENSIONS)
    + [".txt", ".bvh", ".wav.bak", ".npz", "", ".WAVE", ".mp4"]
)
_entries = st.dictionaries(
    st.text("abcxyz_-0123", min_size=1, max_size=6),
    st.tuples(st.sampled_from(_SUFFIXES), st.sampled_from(["file", "folder"])),
    max_size=8,
)


@settings(max_examples=40, deadline=None)
@given(entries=_entries)
def test_speech_files_are_exactly_the_audio_files_directly_inside(entries):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        expected = []
        for stem, (suffix, kind) in entries.items():
            path = folder / f"{stem}{suffix}"
            if kind == "folder":  # a folder named like speech is not speech, nor is what it holds
                path.mkdir()
                (path / "inner.wav").write_bytes(b"")
            else:
                path.write_bytes(b"")
                if suffix.lower() in AUDIO_EXTENSIONS:
                    expected.append(path)
        found = speech_files(folder)
        assert found == sorted(expected)
        assert all(p.parent == folder for p in found)


def test_speech_files_of_something_that_is_not_a_folder_is_refused(tmp_path):
    (tmp_path / "a.wav").write_bytes(b"")
    for path in (tmp_path / "missing", tmp_path / "a.wav"):
        with pytest.raises(InputFileError, match="no such folder") as info:
            speech_files(path)
        assert info.value.path == str(path)


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(order=st.permutations(["x.wav", "speech", "y.flac"]))
def test_expand_speech_keeps_the_order_and_puts_a_folder_s_files_in_its_place(tmp_path, order):
    speech = tmp_path / "speech"
    speech.mkdir(exist_ok=True)
    for name in ("b.ogg", "a.WAV", "notes.txt"):
        (speech / name).write_bytes(b"")
    files = expand_speech([tmp_path / item for item in order])
    expected = []
    for item in order:
        expected += [speech / "a.WAV", speech / "b.ogg"] if item == "speech" else [tmp_path / item]
    assert files == expected  # files named need not exist: they are read (and checked) later


def test_expand_speech_refuses_a_folder_without_speech(tmp_path):
    (tmp_path / "notes.txt").write_bytes(b"")
    with pytest.raises(InputFileError, match=r"no speech files \(\.wav/\.flac/\.ogg/\.mp3\) in this folder") as info:
        expand_speech([tmp_path])
    assert info.value.path == str(tmp_path)


def test_database_folders_lists_the_default_first_then_built_databases(tmp_path, monkeypatch):
    home, cwd = tmp_path / "home", tmp_path / "work"
    monkeypatch.setenv("GESTUREKIT_HOME", str(home))
    for folder in (home / "db" / "b", home / "db" / "a", cwd / "db" / "mine", cwd / "db" / "a"):
        folder.mkdir(parents=True)
        (folder / "database.json").write_text("{}")
    (home / "db" / "empty").mkdir()  # no database.json: not offered
    (cwd / "db" / "notes.json").write_text("{}")
    found = database_folders(cwd=cwd)
    assert list(found.items()) == [
        (str((home / "db" / "demo").resolve()), DEMO_DATABASE_LABEL),
        (str((cwd / "db" / "a").resolve()), "a database you built: a (working folder)"),
        (str((cwd / "db" / "mine").resolve()), "a database you built: mine"),
        (str((home / "db" / "a").resolve()), "a database you built: a"),
        (str((home / "db" / "b").resolve()), "a database you built: b"),
    ]
    for label in found.values():  # said in words: no server path in a label
        assert str(tmp_path) not in label and "/" not in label
    # the home's db folder seen again through the working directory is listed once
    assert list(database_folders(cwd=home)) == [str((home / "db" / n).resolve()) for n in ("demo", "a", "b")]


def test_database_folders_without_any_database_offers_the_default_only(tmp_path, monkeypatch):
    monkeypatch.setenv("GESTUREKIT_HOME", str(tmp_path / "nothing"))
    assert database_folders(cwd=tmp_path / "nowhere") == {
        str((tmp_path / "nothing" / "db" / "demo").resolve()): DEMO_DATABASE_LABEL
    }


@pytest.mark.parametrize(
    "meta, generated",
    [
        ({"build": {"source": "demo (seed 0, 20 min)"}, "takes": []}, True),
        (
            {
                "build": {"source": "/data/takes"},
                "takes": [{"sources": {"generator": "gesturekit.datasets.synthetic"}}],
            },
            True,
        ),
        ({"build": {"source": "/data/takes"}, "takes": [{"sources": {"motion": "a.bvh", "audio": "a.wav"}}]}, False),
        ({}, False),
    ],
)
def test_is_generated_reads_the_build_source_and_the_takes(meta, generated):
    assert is_generated(SimpleNamespace(meta=meta)) is generated


def test_build_database_reads_the_takes_saves_and_records_where_they_came_from(tmp_path, monkeypatch):
    folder, jm = _positions_folder(tmp_path)
    out = tmp_path / "db"
    calls = []
    db = build_database(
        folder,
        out,
        config=BuildConfig(label="two takes"),
        joint_map=jm,
        fps=30.0,
        up="y",
        forward="z",
        units="m",
        check_plausible=False,  # random positions are no body
        progress=lambda *a: calls.append(a),
    )
    assert calls == [(1, 2, "t0"), (2, 2, "t1")]
    assert db.take_names == ["t0", "t1"] and db.n_clips == 4  # 9 s at 15 fps = 135 frames = 2 clips each
    saved = MatchingDatabase.load(out)
    assert saved.take_names == db.take_names and saved.label == "two takes"
    assert saved.meta["build"]["source"] == str(folder.resolve()) and saved.meta["build"]["joint_map"] == str(jm)
    assert not is_generated(saved)
    assert open_database(out).take_names == ["t0", "t1"]
    # the default database, when there is one, is what no path opens (nothing is built)
    monkeypatch.setenv("GESTUREKIT_HOME", str(tmp_path / "home"))
    (tmp_path / "home" / "db").mkdir(parents=True)
    out.rename(tmp_path / "home" / "db" / "demo")
    assert open_database(None).take_names == ["t0", "t1"] and open_database("").n_clips == 4


def test_build_database_never_replaces_a_database_unasked(tmp_path):
    folder, jm = _positions_folder(tmp_path)
    out = tmp_path / "db"
    build_database(folder, out, joint_map=jm, fps=30.0, up="y", forward="z", units="m", check_plausible=False)
    before = {p.name: p.stat().st_mtime_ns for p in out.iterdir()}
    with pytest.raises(OutputError):
        build_database(folder, out, joint_map=jm, fps=30.0, up="y", forward="z", units="m", check_plausible=False)
    assert {p.name: p.stat().st_mtime_ns for p in out.iterdir()} == before


def test_build_database_with_a_bad_joint_map_fails_before_reading_a_take(tmp_path):
    folder, _ = _positions_folder(tmp_path)
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    calls = []
    with pytest.raises(InputFileError) as info:
        build_database(folder, tmp_path / "db", joint_map=bad, fps=30.0, progress=lambda *a: calls.append(a))
    assert str(bad) in str(info.value) and calls == [] and not (tmp_path / "db").exists()


def test_a_take_source_without_speech_is_refused_naming_its_motion_file(tmp_path):
    folder, jm = _positions_folder(tmp_path)
    source = TakeSource("positions", folder / "t0.npy", None)  # made by hand, not discovered
    with pytest.raises(InputFileError, match="no speech file") as info:
        next(iter_takes([source], joint_map=jm, fps_in=30.0))
    assert info.value.path == str(folder / "t0.npy")


def test_takes_are_read_only_with_a_joint_map_of_their_kind(tmp_path):
    folder, jm = _positions_folder(tmp_path)
    with pytest.raises(ConfigError, match="joint-position map, not a BVH joint map"):
        next(iter_takes(discover_takes(folder), joint_map=PRESETS["zeggs"], fps_in=30.0))
    bvh = TakeSource("bvh", tmp_path / "missing.bvh", tmp_path / "missing.wav")  # refused before any read
    with pytest.raises(ConfigError, match="BVH joint map, not a joint-position map"):
        next(iter_takes([bvh], joint_map=load_position_joint_map(jm)))
