"""The on-disk cache of the search's compiled code, shared by processes that compile at once.

numba's own cache lets two processes that compile different specialisations of one function
at the same moment write their machine code under one file name, so that the index of one
names the other's code (a crash in the next process that loads it). These tests start many
processes on a fresh cache, each compiling other specialisations at the same moment, then
start them again to load everything from the cache, and check every result.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gesturekit.search import compile_cache
from tests.waits import patience

REPO = Path(__file__).resolve().parents[2]

#: A module of small kernels: one calls another, so a compile loads and saves a callee's
#: entries while it holds the lock for its own.
TOY = """
import numpy as np
from gesturekit.search.compile_cache import kernel


@kernel()
def weigh(x, w):
    s = 0.0
    for i in range(x.shape[0]):
        s += x[i] * w
    return s


@kernel(fastmath={"reassoc"})
def total(x, w):
    return weigh(x, w) + x.shape[0]
"""

#: One specialisation per process: dtype, read-only or not, contiguous or strided; and the weight's type.
SPECS = [
    (dt, ro, step, wt)
    for dt in ("int16", "int32", "int64", "float32", "float64")
    for ro in (0, 1)
    for step in (1, 2)
    for wt in ("int", "float")
]

CHILD = """
import json, os, random, sys, time
import numpy as np
from numba.core import caching
sys.path.insert(0, sys.argv[1])
specs = json.loads(sys.argv[2])
go = float(sys.argv[3])

# Widen the race: numba's save reads the index, then writes the index and the data file; a
# pause before each write lets other processes read the same index meanwhile (the crash this
# guards against needs that interleaving, which is rare without the pauses).
rand = random.Random(os.getpid())
def paused(write):
    def pause_then(self, *args):
        time.sleep(rand.uniform(0.0, 0.15))
        return write(self, *args)
    return pause_then
caching.IndexDataCacheFile._save_index = paused(caching.IndexDataCacheFile._save_index)
caching.IndexDataCacheFile._save_data = paused(caching.IndexDataCacheFile._save_data)

import toy  # the decorators run: nothing compiles yet
while time.time() < go:  # every process compiles at the same moment
    time.sleep(0.001)
out = []
for dt, ro, step, wt in specs:
    x = (np.arange(40) % 7 - 3).astype(dt)[::step]
    x.flags.writeable = not ro
    w = 3 if wt == "int" else 0.5
    out.append(float(toy.total(x, w)))
print(json.dumps(out))
"""


def _expected(spec, factor: float = 1.0) -> float:
    dt, _, step, wt = spec
    x = (np.arange(40) % 7 - 3).astype(dt)[::step].astype(np.float64)
    return float(factor * (x * (3 if wt == "int" else 0.5)).sum() + x.shape[0])


def _together(script: str, args: list[list[str]], env: dict, *, delay_s: float, timeout_s: float) -> list:
    """Run ``script`` once per argument list, every process starting its work ``delay_s`` from
    now (after every interpreter has started and imported numba); their printed JSON results."""
    go = time.time() + delay_s
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", script, *a, repr(go)],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for a in args
    ]
    results = []
    for p in procs:
        out, err = p.communicate(timeout=timeout_s)
        assert p.returncode == 0, f"a process failed (exit {p.returncode}):\n{err[-3000:]}"
        results.append(json.loads(out))
    return results


def _run_at_once(tmp_path: Path, groups: list[list], env: dict) -> list[list[float]]:
    """Start one process per group of specialisations, all compiling at the same moment; their results."""
    return _together(CHILD, [[str(tmp_path), json.dumps(g)] for g in groups], env, delay_s=2.0, timeout_s=patience(300))


@pytest.fixture
def toy_env(tmp_path):
    (tmp_path / "toy.py").write_text(TOY)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(REPO))
    return env


@pytest.mark.slow
def test_processes_compiling_different_specialisations_at_once_leave_a_whole_cache(tmp_path, toy_env):
    n = 8
    groups = [SPECS[i::n] for i in range(n)]
    for group, got in zip(groups, _run_at_once(tmp_path, groups, toy_env), strict=True):
        assert got == [_expected(s) for s in group]
    folder = next((tmp_path / "cache").iterdir())
    # every specialisation of ``total`` is in the index, each under a file of its own
    assert len(list(folder.glob("toy.total-*.nbc"))) == len(SPECS)
    # then every process loads every specialisation from the cache: each is the right code
    again = _run_at_once(tmp_path, [SPECS[::-1]] * 4, toy_env)
    assert all(got == [_expected(s) for s in SPECS[::-1]] for got in again)
    assert len(list(folder.glob("toy.total-*.nbc"))) == len(SPECS)  # nothing was compiled again


@pytest.mark.slow
def test_a_new_version_of_the_source_gets_its_own_folder_and_never_reads_the_old_code(tmp_path, toy_env):
    spec = [SPECS[0]]
    assert _run_at_once(tmp_path, [spec], toy_env) == [[_expected(spec[0])]]
    # the same function names, another body: what the old code computed must not come back
    (tmp_path / "toy.py").write_text(TOY.replace("s += x[i] * w", "s += 2 * x[i] * w"))
    got = _run_at_once(tmp_path, [spec], toy_env)
    assert got == [[_expected(spec[0], factor=2.0)]]
    assert len(list((tmp_path / "cache").iterdir())) == 2  # the old version's folder was used an instant ago


def test_the_folder_is_keyed_by_the_source_and_numba(tmp_path, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "c"))
    monkeypatch.setattr(compile_cache.numba.config, "CACHE_DIR", str(tmp_path / "c"))
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("x = 1\n")
    b.write_text("x = 2\n")
    fa, fb = compile_cache.cache_folder(a), compile_cache.cache_folder(b)
    assert fa.parent == fb.parent == tmp_path / "c"
    assert fa.name.startswith("a-") and fb.name.startswith("b-")
    assert fa.name[2:] != fb.name[2:]  # another content, another digest
    a.write_text("x = 3\n")
    assert compile_cache.cache_folder(a) == fa  # the version this process saw first is kept


def test_folders_of_old_versions_are_pruned_unless_in_use(tmp_path):
    base = tmp_path / "c"
    new = base / "kernels-0123456789abcdef"
    stale, recent, held, other = (
        base / n
        for n in (
            "kernels-aaaaaaaaaaaaaaaa",
            "kernels-bbbbbbbbbbbbbbbb",
            "kernels-cccccccccccccccc",
            "toy-dddddddddddddddd",
        )
    )
    for d in (new, stale, recent, held, other):
        d.mkdir(parents=True)
        (d / compile_cache.LOCK_NAME).touch()
    old = time.time() - compile_cache.STALE_S - 60
    for d in (stale, held, other):
        os.utime(d / compile_cache.LOCK_NAME, (old, old))
    with compile_cache._FolderLock.hold(held):  # a process of that version is loading its code
        os.utime(held / compile_cache.LOCK_NAME, (old, old))
        compile_cache._prune(new, time.time())
    assert not stale.exists()
    assert recent.is_dir() and held.is_dir() and other.is_dir() and new.is_dir()


def test_a_planted_lock_link_is_never_followed(tmp_path):
    target = tmp_path / "thesis.txt"
    target.write_bytes(b"four years of work")
    folder = tmp_path / "c" / "kernels-0123456789abcdef"
    folder.mkdir(parents=True)
    (folder / compile_cache.LOCK_NAME).symlink_to(target)
    with pytest.raises(OSError):
        compile_cache._open_lock(folder)
    assert target.read_bytes() == b"four years of work"


def test_the_search_kernels_use_the_safe_cache(monkeypatch):
    from gesturekit.search import kernels, reduced_kernels

    for module, names in (
        (kernels, ("survivors", "rank_top", "dot32_at", "reduce_many", "admissible_ends")),
        (reduced_kernels, ("scan_reduced", "reduce_clips", "reduced_estimate")),
    ):
        for name in names:
            cache = getattr(module, name)._cache
            assert isinstance(cache, compile_cache._LockedCache), name
            assert Path(cache.cache_path) == compile_cache.cache_folder(module.__file__)


def test_kernel_refuses_a_cache_option():
    with pytest.raises(TypeError, match="cache"):
        compile_cache.kernel(cache=True)


SEARCHER = """
import hashlib, json, sys, time
import numpy as np
from gesturekit.database import MatchingDatabase
from gesturekit.synthesis import SynthesisConfig, synthesize, synthesize_batch
folder, kinds, go = sys.argv[1], json.loads(sys.argv[2]), float(sys.argv[3])
rng = np.random.default_rng(7)
speech = [rng.normal(0, 0.1, 16000 * 4).astype(np.float32) for _ in range(2)]
db = MatchingDatabase.load(folder)
while time.time() < go:
    time.sleep(0.001)
out = {}
for kind in kinds:
    if kind == "memory":  # writable arrays: other specialisations than a folder's read-only ones
        mem = MatchingDatabase.load(folder, mmap=False)
        res = [synthesize(speech[0], db=mem, config=SynthesisConfig(record=1))]
    elif kind == "control":
        res = [synthesize(speech[0], db=db, config=SynthesisConfig(control="0-2:left_hand=high"))]
    elif kind == "batch":
        res = synthesize_batch(speech, db=db, config=SynthesisConfig())
    else:
        res = [synthesize(speech[0], db=db, config=SynthesisConfig(record=1))]
    out[kind] = [hashlib.sha256(np.ascontiguousarray(r.motion.positions).tobytes()).hexdigest() for r in res]
print(json.dumps(out))
"""


@pytest.mark.slow
def test_searches_started_together_on_a_fresh_cache_agree(tmp_path):
    """The real search kernels: four processes on a fresh cache, each compiling other
    specialisations (read-only and writable arrays, one query and a batch, with a control),
    then four more loading them all: no crash, and the same motion everywhere."""
    from gesturekit.demo import build_demo_database

    folder = tmp_path / "db"
    build_demo_database(folder, minutes=1.0)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=str(REPO))
    kinds = ["folder", "memory", "batch", "control"]

    def run(groups):
        return _together(SEARCHER, [[str(folder), json.dumps(g)] for g in groups], env, delay_s=4.0, timeout_s=600)

    first = {k: v for out in run([[k] for k in kinds]) for k, v in out.items()}
    assert first["memory"] == first["folder"]  # the same database in memory or mapped: the same motion
    for out in run([kinds[::-1], kinds, kinds[1:] + kinds[:1], kinds[::-1]]):
        assert out == first
