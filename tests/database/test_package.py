"""The database package: one builder, a frozen config, and no import circle.

The in-memory build assembles the database's arrays without a temporary folder, and what it
gives is what the folder build writes: every array, every statistic and every entry of
``database.json`` of the folder built and loaded, and, saved, the folder's bytes.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import json
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.database.build import MemoryOut, assemble
from gesturekit.database.clips import MOMENT_KEYS, TakeClips
from gesturekit.database.folder import CLIP_ARRAYS, FolderOut
from gesturekit.database.stage import StagedTake, stage_take
from gesturekit.errors import ConfigError
from gesturekit.features import LAYOUT
from tests.conftest import make_take

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "gesturekit"


# ---- the import graph ------------------------------------------------------------------------------


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_module(name: str) -> bool:
    path = ROOT.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _imports(path: Path) -> list[tuple[str, list[str]]]:
    """Every gesturekit import of a file, ``TYPE_CHECKING`` ones included: (module, names imported)."""
    me = _module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(a.name, []) for a in node.names if a.name.split(".")[0] == "gesturekit"]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            if source.split(".")[0] != "gesturekit":
                continue
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                out.append((sub, []) if _is_module(sub) else (source, [alias.name]))
    return out


def _graph() -> dict[str, set[str]]:
    graph = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        me = _module_name(path)
        graph[me] = {m for m, _ in _imports(path)} - {me}
    return graph


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next((c for c in children if c in graph), None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == v:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def test_the_circle_finder_finds_a_circle_through_type_checking():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert _circles(graph) == [["a", "b", "c"]]
    assert _circles({"a": {"b"}, "b": set()}) == []


@pytest.mark.slow
def test_no_import_circle_runs_through_the_database_package():
    """Counting every import, those under ``if TYPE_CHECKING:`` too."""
    circles = [c for c in _circles(_graph()) if any(m.startswith("gesturekit.database") for m in c)]
    assert circles == []


@pytest.mark.slow
def test_no_module_imports_a_private_name_of_another_module_of_the_database():
    reaching = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for module, names in _imports(path):
            private = [n for n in names if n.startswith("_") and n != "__version__"]
            inside = module.startswith("gesturekit.database") or _module_name(path).startswith("gesturekit.database")
            if private and inside:
                reaching.append(f"{_module_name(path)} imports {', '.join(private)} from {module}")
    assert reaching == []


@pytest.mark.parametrize(
    "old",
    [
        "gesturekit._database_build",
        "gesturekit._database_stage",
        "gesturekit._database_folder",
        "gesturekit._database_audio",
        "gesturekit._database_from_folder",
    ],
)
def test_the_flat_database_modules_are_gone(old):
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)


def test_the_package_gives_what_users_import():
    import gesturekit
    import gesturekit.database as database

    assert gesturekit.MatchingDatabase is database.MatchingDatabase is database.matching.MatchingDatabase
    assert gesturekit.BuildConfig is database.BuildConfig is database.config.BuildConfig
    assert database.FORMAT_VERSION == database.folder.FORMAT_VERSION == 1
    for name in database.__all__:
        assert getattr(database, name) is not None


# ---- the frozen config ------------------------------------------------------------------------------


def test_build_config_is_frozen_and_a_changed_one_is_checked_again():
    config = BuildConfig(overlap_stride=8, percentiles=(10, 90))
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.label = "changed"  # type: ignore[misc]
    assert config.percentiles == (10.0, 90.0) and all(type(p) is float for p in config.percentiles)
    assert config == BuildConfig(overlap_stride=8, percentiles=(10.0, 90.0))
    relabelled = dataclasses.replace(config, label="two takes")
    assert (relabelled.label, config.label, relabelled.overlap_stride) == ("two takes", "", 8)
    with pytest.raises(ConfigError, match="overlap_stride must be in 1..32"):
        dataclasses.replace(config, clip_frames=32, overlap_stride=40)
    with pytest.raises(ConfigError, match="keeps no audio"):
        dataclasses.replace(config, store_audio=False, audio_format="flac")


# ---- the in-memory build and the folder build -------------------------------------------------------


def _json(value: object) -> object:
    return json.loads(json.dumps(value))


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _folder_build(takes, config: BuildConfig, tmp: Path) -> Path:
    """The folder build's two passes: each take staged on disk, then assembled file by file."""
    staged = []
    for i, take in enumerate(takes):
        unit = tmp / "staging" / f"{i:03d}"
        unit.mkdir(parents=True)
        staged.append(StagedTake(unit, stage_take(take, unit, 0, config)))
    staged.sort(key=lambda s: s.name)
    out = tmp / "folder"
    out.mkdir()
    assemble(FolderOut(out), staged, config)
    return out


CONFIGS = {
    "overlap+pcm": BuildConfig(overlap_stride=16, label="in memory", source="tests"),
    "flac-8k": BuildConfig(clip_frames=32, audio_format="flac", audio_rate=8000, percentiles=(5, 95)),
    "no-audio": BuildConfig(store_audio=False),
}


@pytest.mark.parametrize("which", list(CONFIGS))
def test_the_in_memory_build_is_the_folder_build_loaded(which, tmp_path, monkeypatch):
    config = CONFIGS[which]
    takes = [make_take(7.0, seed=3, name="b"), make_take(9.0, seed=1, name="a"), make_take(5.0, seed=2, name="c")]
    folder = _folder_build(takes, config, tmp_path)

    def no_temporary(*args, **kwargs):
        raise AssertionError("the in-memory build made a temporary folder")

    with monkeypatch.context() as m:
        m.setattr(tempfile, "mkdtemp", no_temporary)
        m.setattr(tempfile, "TemporaryDirectory", no_temporary)
        db = MatchingDatabase.build(takes, config=config)
    loaded = MatchingDatabase.load(folder)

    assert list(db.arrays) == list(loaded.arrays)
    for k in loaded.arrays:
        assert db.arrays[k].dtype == loaded.arrays[k].dtype, k
        np.testing.assert_array_equal(db.arrays[k], loaded.arrays[k], err_msg=k)
    assert (db.overlap is None) == (loaded.overlap is None) == (config.overlap_stride is None)
    for k in loaded.overlap or {}:
        np.testing.assert_array_equal((db.overlap or {})[k], (loaded.overlap or {})[k], err_msg=f"overlap/{k}")
    assert list(db.stats) == list(loaded.stats)
    for k in loaded.stats:
        assert db.stats[k].tobytes() == loaded.stats[k].tobytes(), k
    assert (db.audio is None) == (loaded.audio is None) == (not config.store_audio)
    if loaded.audio is not None:
        assert db.audio is not None and db.audio.dtype == loaded.audio.dtype
        np.testing.assert_array_equal(db.audio, loaded.audio)
        np.testing.assert_array_equal(db.take_audio("a"), loaded.take_audio("a"))
    # every entry of database.json but the counts, which writing adds
    written = dict(loaded.meta)
    assert written.pop("counts") == {"clips": db.n_clips, "takes": 3}
    assert _json(db.meta) == written
    assert db.take_names == ["a", "b", "c"] and db.thresholds == loaded.thresholds
    # and saving the in-memory database writes the folder the build wrote, byte for byte
    db.save(tmp_path / "saved")
    assert _files(tmp_path / "saved") == _files(folder)


def _synthetic_take(name: str, n_clips: int, n_windows: int, count: int, L: int, seed: int) -> TakeClips:
    """A take's rows of the right shapes with random values (no audio or motion behind them)."""
    rng = np.random.default_rng(seed)
    n_frames = max(n_clips * L, 1)
    rows = {
        "F": (L, LAYOUT.audio_dim),
        "P": (L, LAYOUT.pose_dim),
        "G": (L, LAYOUT.motion_dim),
        "A": (L, LAYOUT.cgan_audio_dim),
        "attributes": (L, 9),
        "pose_track": (L + LAYOUT.pose_lookahead, 24),
    }
    arrays: dict[str, np.ndarray] = {}
    for prefix, n in (("", n_clips), ("overlap.", n_windows)):
        for k in CLIP_ARRAYS:
            arrays[prefix + k] = (
                rng.random((n, L)) < 0.5 if k == "valid" else rng.normal(size=(n, *rows[k])).astype(np.float32)
            )
        arrays[prefix + "clip_start"] = (np.arange(n) * L).astype(np.int32)
    samples = n_frames * 16000 // 15
    arrays["audio"] = rng.integers(-3000, 3000, samples).astype(np.int16)
    dims = {"F": LAYOUT.audio_dim, "P": LAYOUT.pose_dim, "A": LAYOUT.cgan_audio_dim}
    for key in MOMENT_KEYS:
        arrays[f"moments_{key}"] = np.stack([rng.normal(size=dims[key]), rng.random(dims[key]) * count + 0.1])
    record = {
        "index": 0,
        "name": name,
        "sources": {"generator": "tests"},
        "n_frames": n_frames,
        "n_clips": n_clips,
        "n_windows": n_windows,
        "audio_samples": samples,
        "audio_size": samples,
        "count": count,
        "joints": None,
        "seconds": n_frames / 15,
    }
    return TakeClips(record, arrays)


@settings(max_examples=25, deadline=None)
@given(
    shapes=st.lists(st.tuples(st.integers(0, 3), st.integers(0, 5), st.integers(0, 40)), min_size=1, max_size=4)
    .filter(lambda s: any(c for c, _, _ in s))
    .filter(lambda s: any(n for _, _, n in s)),
    overlap=st.booleans(),
    seed=st.integers(0, 2**31 - 1),
)
def test_assembling_in_memory_gives_the_arrays_assembling_into_a_folder_writes(shapes, overlap, seed):
    """For any takes (some of no clip, some with no frame in the moments), the two outputs of
    :func:`assemble` hold the same arrays, statistics and ``database.json``."""
    config = BuildConfig(clip_frames=16, overlap_stride=8 if overlap else None)
    takes = [_synthetic_take(f"t{i}", c, w if overlap else 0, n, 16, seed + i) for i, (c, w, n) in enumerate(shapes)]
    memory = MemoryOut()
    meta, stats = assemble(memory, takes, config)
    parts = memory.parts()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        folder_meta, folder_stats = assemble(FolderOut(folder), takes, config)
        assert (
            _json(meta)
            == _json(folder_meta)
            == {k: v for k, v in json.loads((folder / "database.json").read_text()).items() if k != "counts"}
        )
        for k in stats:
            assert stats[k].tobytes() == folder_stats[k].tobytes() == parts["stats"][k].tobytes()
        for cut, arrays in (("", parts["arrays"]), ("overlap", parts["overlap"])):
            if arrays is None:
                assert not overlap and not (folder / "overlap").exists()
                continue
            for k, a in arrays.items():
                on_disk = np.load(folder / cut / f"{k}.npy", allow_pickle=False)
                assert a.dtype == on_disk.dtype and a.tobytes() == on_disk.tobytes(), f"{cut}/{k}"
        np.testing.assert_array_equal(parts["audio"], np.load(folder / "audio.npy", allow_pickle=False))
