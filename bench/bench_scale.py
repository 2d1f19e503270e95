"""Scale benchmark: build and search a database of H hours of demo takes written to disk as BVH and wav.

The demo speaker's takes are written as BVH files (30 fps, so reading and resampling
them is timed as for captured data) and 16 kHz wav files to a temporary folder; then
for two sizes, H/2 and H hours, it prints, measured in this one run:

* the build (``gesturekit.workspace.build_database``, in a subprocess) with 1 worker
  and with all workers (where the build takes ``workers``), as a multiple of real
  time, and its peak resident memory (the process, and its largest worker);
* the database's size on disk and the stored audio's share of it (and what FLAC or
  8 kHz storage would make of it);
* the time to open it, a search step vs one float32 matrix-vector product over the
  pose matrix read from the disk cache (target <= 1.0x), 60 s of speech end to end
  (``synthesize``; target <= 2 s at 100 hours) vs 113 such products (each run bracketed by
  products, as the steps are), and the memory the search allocates beyond the database, its
  copy of the pose features included (the frame copy, or the 8-bit one; target < 25 %);

then a projection to 100 hours from the slope between the two sizes. With
``--tile-hours T`` the search figures are also measured on the larger database
repeated to T hours on disk (the scan's work does not depend on the clips repeating; the
decisions do more, as repeated clips tie exactly).

With ``--bounds FOLDER`` it prints, for the first steps of a synthesis on that database, how
many clips bounds per clip or per block of starts could leave unread without changing the step's
table (``docs/METHOD.md``, "Exact arithmetic"): a clip may be left unread only when it is known to
lie after every listed clip in both rankings, so it prints the deciding clips' largest pose and audio
distances and the share of clips that spheres per block of starts place beyond the first, and that
also the audio, at every start those spheres leave open, places beyond the second (exact minima:
the best any audio bound could do; and the bound of a cone around each block's audio directions).

With ``--lowd FOLDER`` it prints, for steps of a synthesis of real speech (``--speech``; by default
BEAT speech from ``../shared/data/speech``), what a first pass over a PCA projection of the pose
features to 8 to 32 dimensions, with the residual norm of each frame (an interval on every distance),
could decide before today's tiers: the clips whose nearest start it decides, the starts it leaves, the
float32 rows the 8-bit tier still reads among them, the clips the skip rule still has to read, the bytes
a step would read; and today's scan timed against the same scan on the starts such a pass leaves, the
same scan given only each clip's nearest start, and one float32 matrix-vector product.

Usage: python bench/bench_scale.py --hours 1 [--workers N] [--keep] [--tile-hours 100]
       python bench/bench_scale.py --search-only FOLDER   (the search figures of a database folder)
       python bench/bench_scale.py --search-only FOLDER --device cuda   (also the search with its scan on a GPU)
       python bench/bench_scale.py --bounds FOLDER [--block 8]   (what skipping clips could save)
       python bench/bench_scale.py --lowd FOLDER [--speech FILE] [--steps 9]   (what a low-d first pass could save)
"""

from __future__ import annotations

import argparse
import filecmp
import inspect
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import tracemalloc
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from bench_search import BLAS_IDLE, best_of, device_share, step_vs_matvec

FPS_BVH = 30.0
#: Real speech for ``--lowd`` (the shared test data, read in place; absent: generated speech is used)
SPEECH = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "speech" / "beat_lawrence_0_19_19.wav"
STEPS_60S = 113  # 60 s of speech at 15 fps in steps of 8 frames

# the build, in a fresh process so that its peak resident memory is its own
_CHILD = """
import inspect, json, resource, sys, time
from gesturekit.workspace import build_database
a = json.loads(sys.argv[1])
kw = {"workers": a["workers"]} if "workers" in inspect.signature(build_database).parameters else {}
t0 = time.perf_counter()
db = build_database(a["folder"], a["out"], joint_map=a["map"], **kw)
dt = time.perf_counter() - t0
# VmHWM: this process's own peak (ru_maxrss also holds the bench's memory at the fork that started it)
hwm = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM"))
kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps({"seconds": dt, "rss": hwm * 1024, "rss_workers": kids * 1024, "clips": db.n_clips}))
"""


def machine() -> str:
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return (
        f"machine: {os.cpu_count()} cores, {mem:.0f} GiB RAM, {platform.machine()}, GPU none (CPU only); "
        f"python {platform.python_version()}, numpy {np.__version__}; "
        f"load average {' '.join(f'{x:.1f}' for x in os.getloadavg())}"
    )


def _write_take(job: tuple[Path, str, float, int]) -> float:
    """Write one demo take as ``name.bvh`` (30 fps) and ``name.wav`` (16 kHz int16); returns its seconds."""
    import soundfile as sf

    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.errors import GestureKitWarning
    from gesturekit.export.bvh import write_bvh
    from gesturekit.motion import Motion, resample_positions

    folder, name, seconds, seed = job
    take, _ = generate_demo_take(seconds=seconds, seed=seed, name=name)
    pos = resample_positions(take.motion.positions, take.motion.fps, FPS_BVH).astype(np.float32)
    with warnings.catch_warnings():
        # positions interpolated to 30 fps shorten bones between frames; the BVH keeps one length
        # per bone, as a 30 fps capture would have: its reported error is not this bench's subject
        warnings.simplefilter("ignore", GestureKitWarning)
        write_bvh(folder / f"{name}.bvh", Motion(pos, FPS_BVH))
    sf.write(folder / f"{name}.wav", take.audio, 16000, subtype="PCM_16")
    return seconds


def write_takes(root: Path, hours: float, take_seconds: float, workers: int) -> tuple[Path, Path, float, float]:
    """Takes of ``hours`` in ``root/all`` and hard links to the first half of them in ``root/half``.

    Returns (half folder, all folder, seconds in half, seconds in all).
    """
    n = max(2, round(hours * 3600 / take_seconds))
    half, full = root / "half", root / "all"
    half.mkdir()
    full.mkdir()
    jobs = [(full, f"take{k:05d}", take_seconds, 1000 + k) for k in range(n)]
    with ProcessPoolExecutor(workers) as pool:
        secs = list(pool.map(_write_take, jobs))
    for _, name, _, _ in jobs[: n // 2]:
        for ext in (".bvh", ".wav"):
            os.link(full / f"{name}{ext}", half / f"{name}{ext}")
    return half, full, float(sum(secs[: n // 2])), float(sum(secs))


def joint_map(root: Path) -> Path:
    """A JSON joint map for the BVH files gesturekit writes (its own joint names)."""
    from gesturekit.skeleton import JOINT_NAMES

    path = root / "gesturekit-joints.json"
    path.write_text(json.dumps({"pelvis": JOINT_NAMES[0], "joints": {n: n for n in JOINT_NAMES}}))
    return path


def build(folder: Path, out: Path, jmap: Path, workers: int | None) -> dict:
    arg = json.dumps({"folder": str(folder), "out": str(out), "map": str(jmap), "workers": workers})
    run = subprocess.run([sys.executable, "-c", _CHILD, arg], capture_output=True, text=True, check=False)
    if run.returncode != 0:
        raise SystemExit(f"the build of {folder} failed:\n{run.stderr[-3000:]}")
    return json.loads(run.stdout.strip().splitlines()[-1])


def folder_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def anon_rss() -> int:
    """Resident memory not backed by files (the database's memory-mapped pages are not in it), bytes."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("RssAnon:"):
                return int(line.split()[1]) * 1024
    return 0


class AnonPeak:
    """The largest :func:`anon_rss` seen while the block runs, sampled every 2 ms."""

    def __enter__(self) -> AnonPeak:
        self.base = self.peak = anon_rss()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()
        return self

    def _watch(self) -> None:
        while not self._stop.wait(0.002):
            self.peak = max(self.peak, anon_rss())

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()
        self.peak = max(self.peak, anon_rss())


def audio_options(path: Path) -> str:
    """What FLAC and 8 kHz storage would make of the stored audio, encoded take by take."""
    from gesturekit.database import MatchingDatabase
    from gesturekit.database.audio import AudioStorage, encode_take_audio

    db = MatchingDatabase.load(path)
    if db.audio is None:
        return "no audio stored"
    raw = int(db.audio.nbytes)
    sizes = {}
    for s in (AudioStorage("flac"), AudioStorage("pcm", 8000), AudioStorage("flac", 8000)):
        sizes[s] = sum(
            encode_take_audio(db.audio[t["audio_offset"] :][: t["audio_samples"]], s).data.nbytes
            for t in db.meta["takes"]
        )
    return ", ".join(f"{s.format} {s.rate // 1000} kHz {n / raw:.0%}" for s, n in sizes.items()) + " of int16 16 kHz"


def search_figures(path: Path, runs: int) -> dict:
    """Open, per step vs mat-vec, 60 s end to end, and memory beyond the database, on the database at ``path``."""
    from gesturekit.database import MatchingDatabase
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.search import SearchConfig, SearchIndex
    from gesturekit.synthesis import synthesize, synthesizer_for

    speech = generate_demo_take(seconds=60.0, seed=7, name="query")[0].audio
    # compiled kernels and lazy imports load outside the measurements, on another instance of the database
    synthesize(speech[: 4 * 16000], db=MatchingDatabase.load(path))
    t_open = best_of(lambda: MatchingDatabase.load(path), 3)
    db = MatchingDatabase.load(path)
    P2 = db.P.reshape(-1, db.P.shape[-1])
    searched = P2.nbytes + db.F.nbytes + db.valid.nbytes
    for a in (db.P, db.F, db.valid, db.G, db.attributes):  # into the disk cache, as a database in use is
        for i in range(0, a.shape[0], 4096):
            np.asarray(a[i : i + 4096]).max()
    tracemalloc.start()
    with AnonPeak() as mem:
        t0 = time.perf_counter()
        first = synthesize(speech, db=db)  # prepares the search index (kept for the database)
        t_first = time.perf_counter() - t0
    traced = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    index = synthesizer_for(db).index  # the one synthesize built
    assert isinstance(index, SearchIndex) and np.may_share_memory(index._P3, db.P), "the index copied the pose matrix"
    # 60 s of speech, each run bracketed by products like a step (the same machine state for both)
    P2c = np.asarray(P2)
    q = np.array(P2c[min(12345, P2c.shape[0] - 1)], dtype=np.float32)
    out = np.empty(P2c.shape[0], np.float32)
    e2e_runs, e2e_ratios = [], []
    for _ in range(3):
        g0 = best_of(lambda: np.dot(P2c, q, out=out), 3)
        time.sleep(BLAS_IDLE)
        t0 = time.perf_counter()
        synthesize(speech, db=db)
        e2e_runs.append(time.perf_counter() - t0)
        g1 = best_of(lambda: np.dot(P2c, q, out=out), 3)
        e2e_ratios.append(e2e_runs[-1] / (STEPS_60S * 0.5 * (g0 + g1)))
    t_e2e = float(np.median(e2e_runs))
    cfg = SearchConfig(k=0, segment=8, seed=1)
    query = first.plan.query
    t_step, t_gemv, ratios = step_vs_matvec(index, P2, query, cfg, runs=runs)
    return {
        "open": t_open,
        "frames": P2.shape[0],
        "searched": searched,
        "folder": folder_bytes(path),
        "step": t_step,
        "gemv": t_gemv,
        "ratio": float(np.median(ratios)),
        "e2e": t_e2e,
        "e2e_ratio": float(np.median(e2e_ratios)),
        "e2e_first": t_first,
        "traced": traced,
        "anon": mem.peak - mem.base,
        "copy": "frame copy" if index._frames is not None else "8-bit copy",
    }


def device_figures(path: Path, device: str, runs: int) -> None:
    """Print the search of 60 s of speech with its scan on a torch ``device``, against the same search here.

    The search alone (the speech's features made once, outside the timing), on an index prepared for each:
    per step vs one float32 matrix-vector product on the CPU, and the 113 steps; the two results are checked
    equal first.
    """
    from gesturekit.database import MatchingDatabase
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.search import SearchConfig, SearchIndex
    from gesturekit.synthesis import synthesize

    db = MatchingDatabase.load(path)
    speech = generate_demo_take(seconds=60.0, seed=7, name="query")[0].audio
    query = synthesize(speech, db=db).plan.query  # the search's own query features of this speech
    cfg = SearchConfig(k=0, segment=8, seed=1)
    here = SearchIndex(db.P, db.F, db.valid)
    t0 = time.perf_counter()
    there = SearchIndex(db.P, db.F, db.valid, device=device)
    t_place = time.perf_counter() - t0
    same = there.search(query, config=cfg).equals(here.search(query, config=cfg))
    assert same, "the search on the device and here disagree"
    P2 = db.P.reshape(-1, db.P.shape[-1])
    for label, index in ((device, there), ("this CPU", here)):
        t_step, t_gemv, ratios = step_vs_matvec(index, P2, query, cfg, runs=runs)
        t_60 = best_of(lambda index=index: index.search(query, config=cfg), 2)
        print(
            f"  scan on {label}: step {t_step * 1e3:.2f} ms = {np.median(ratios):.2f}x one float32 mat-vec on the "
            f"CPU ({t_gemv * 1e3:.1f} ms); 60 s of speech, the search alone: {t_60:.2f} s (target <= 2 s at 100 h)"
        )
    t_all, t_there = device_share(there, query, cfg)
    print(
        f"  of one search on {device}, {t_all:.2f} s: the scan there (product, per-clip reduction, copies back) "
        f"{t_there:.2f} s, the decisions here {t_all - t_there:.2f} s (what a faster device cannot shorten)"
    )
    print(f"  (the features placed on {device} in {t_place:.2f} s; both searches gave the same result)")


def bound_figures(path: Path, steps: int = 9, block: int = 8, width: int = 10) -> None:
    """Print, per step of 12 s of speech, the share of clips that bounds could leave unread.

    A clip left unread must lie after every deciding clip (combined rank at most the table's
    last, ``width`` rows) in both rankings: then their ranks do not count it, and its own
    combined rank exceeds theirs by 2 at least (tests/search/test_skip_rule.py). The figures
    are what the rule allows with the deciding clips known: an upper bound on what a search that
    must first find them could leave unread. Per block of ``block`` starts: a sphere around the
    admissible starts' pose features (float64 centre, largest radius) bounds the block's pose
    distances; the blocks whose lower bound is above the least upper bound of the clip cannot
    hold its nearest start. The audio
    distances at the other blocks' starts are taken exactly (the best any audio bound could do)
    and bounded by a cone around each block's unit audio directions. Every distance is float64.
    """
    from gesturekit.database import MatchingDatabase
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.search.admissible import base_starts
    from gesturekit.synthesis import synthesize

    db = MatchingDatabase.load(path)
    speech = generate_demo_take(seconds=12.0, seed=7, name="query")[0].audio
    res = synthesize(speech, db=db)
    chosen, query = res.search, res.plan.query
    M, T, D = db.P.shape
    N = chosen.config.segment
    nb = T // block
    adm_all = base_starts(np.asarray(db.valid), N)
    print(f"bounds of {path}: {M} clips; blocks of {block} starts; {width} rows listed; exact distances in float64")
    for i in range(1, min(steps + 1, chosen.clip.size)):
        p = np.asarray(db.P[chosen.clip[i - 1], chosen.start[i - 1] + N - 1], np.float64)
        f = np.asarray(query[i * N], np.float64)
        f /= np.linalg.norm(f)
        d_near, a_near = np.full(M, np.inf), np.full(M, np.inf)
        pose_lb, audio_open, audio_cone = np.full(M, np.inf), np.full(M, np.inf), np.full(M, np.inf)
        for c0 in range(0, M, 2048):
            c1 = min(M, c0 + 2048)
            P = np.asarray(db.P[c0:c1], np.float64)
            U = np.asarray(db.F[c0:c1], np.float64)
            U /= np.maximum(np.linalg.norm(U, axis=-1, keepdims=True), 1e-300)
            adm = adm_all[c0:c1]
            d2 = ((P - p) ** 2).sum(-1)
            d2[~adm | (d2 == 0)] = np.inf
            cos = 1.0 - U @ f
            s = d2.argmin(1)
            rows = np.arange(c1 - c0)
            d_near[c0:c1] = d2[rows, s]
            a_near[c0:c1] = np.where(np.isfinite(d_near[c0:c1]), cos[rows, s], np.inf)
            ab = adm[:, : nb * block].reshape(-1, nb, block)
            cnt = ab.sum(-1)
            Pb = P[:, : nb * block].reshape(-1, nb, block, D)
            cen = (Pb * ab[..., None]).sum(2) / np.maximum(cnt, 1)[..., None]
            rad = np.sqrt((((Pb - cen[:, :, None]) ** 2).sum(-1) * ab).max(-1))
            dc = np.sqrt(((cen - p) ** 2).sum(-1))
            lb = np.where(cnt > 0, np.maximum(dc - rad, 0.0) ** 2, np.inf)
            ub = np.where(cnt > 0, (dc + rad) ** 2, np.inf)
            open_ = lb <= ub.min(1, keepdims=True)
            pose_lb[c0:c1] = np.where(open_, lb, np.inf).min(1)
            cb = np.where(adm, cos, np.inf)[:, : nb * block].reshape(-1, nb, block).min(-1)
            audio_open[c0:c1] = np.where(open_, cb, np.inf).min(1)
            Ub = U[:, : nb * block].reshape(-1, nb, block, U.shape[-1])
            axis = (Ub * ab[..., None]).sum(2)
            axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-300)
            half = np.arccos(np.clip(np.where(ab, (Ub * axis[:, :, None]).sum(-1), 1.0).min(-1), -1, 1))
            gap = np.arccos(np.clip(axis @ f, -1, 1))
            audio_cone[c0:c1] = np.where(open_, 1.0 - np.cos(np.maximum(gap - half, 0.0)), np.inf).min(1)
        idx = np.flatnonzero(np.isfinite(d_near))
        d, a = d_near[idx], a_near[idx]
        pose_rank = np.empty(idx.size, np.int64)
        pose_rank[np.lexsort((idx, d))] = np.arange(idx.size)
        audio_rank = np.empty(idx.size, np.int64)
        audio_rank[np.lexsort((idx, a))] = np.arange(idx.size)
        combined = pose_rank + audio_rank
        # the deciding clips: combined rank at most the table's last (ties included)
        listed = np.flatnonzero(combined <= np.sort(combined)[min(width, idx.size) - 1])
        d_top, a_top = d[listed].max(), a[listed].max()
        far = pose_lb[idx] > d_top
        shares = [np.mean(d > d_top), far.mean(), np.mean(far & (a > a_top))]
        shares += [np.mean(far & (audio_open[idx] > a_top)), np.mean(far & (audio_cone[idx] > a_top))]
        print(
            f"  step {i}: {idx.size} clips; deciding ranks up to {pose_rank[listed].max()} (pose), "
            f"{audio_rank[listed].max()} (audio); clips beyond the deciding ones: by pose at the nearest start "
            "{:.1%}, by the block spheres {:.1%}, and by audio at the nearest start {:.1%}, "
            "at every open start {:.1%}, by the cones {:.1%}".format(*shares)
        )


#: Dimensions of the projection ``--lowd`` measures, and how it stores each frame's coordinates:
#: float32, or int8 / int4 codes with a scale per frame (the largest code).
LOWD_DIMS = (8, 16, 24, 32)
LOWD_CODES = {"float32": 0, "int8": 127, "int4": 7}


def lowd_bytes(d: int, storage: str) -> float:
    """Bytes a frame of a low-d copy: its coordinates, then |y|^2 and the residual norm (float32),
    and for codes their scale and rounding loss too."""
    return 4 * d + 8 if storage == "float32" else d * (1 if storage == "int8" else 0.5) + 16


def _open_starts(est: np.ndarray, err: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """The starts of ``starts`` (n, T) the 8-bit tier leaves open (as ``scan_reduced`` decides them):
    within twice the clip's bound ``err`` (n,) of its least estimate, or all where that could be zero."""
    e = np.where(starts, est, np.inf)
    least = e.min(axis=1)
    with np.errstate(invalid="ignore"):
        near = starts & (e <= (least + 2 * err)[:, None])
    return np.where((least <= err)[:, None], starts, near)


def _timed_scan(index, q: np.ndarray, f: np.ndarray, bias: np.ndarray, pool, scratch: dict) -> float:
    """Seconds of one query's scan of ``index`` (``SearchIndex._scan``) with the admissible starts ``bias``
    (``scratch`` keeps its buffer between calls, as a search does between steps)."""
    t0 = time.perf_counter()
    index._scan(q[None], [bias], f[None], scratch, pool)
    return time.perf_counter() - t0


def lowd_figures(path: Path, speech: Path | None, steps: int = 9, runs: int = 3) -> None:
    """Print what a low-dimensional first pass over the pose features could decide, per step, and time it.

    The pass: a PCA basis ``V`` (d of the 96 dimensions) of the frames' deviations from their clip's
    mean ``c_m``; per frame ``y = V^T (p - c_m)``, stored as float32 or as int8 / int4 codes with a
    scale (losing ``e = |y - y~|``), and the residual norm ``r = |p - c_m - V y|``; per clip and query
    ``a = |q - c_m - V V^T (q - c_m)|``. For an orthogonal projection, with ``g = |V^T (q - c_m) - y~|``,
    ``max(0, g - e)^2 + (a - r)^2 <= |q - p|^2 <= (g + e)^2 + (a + r)^2``. A start whose lower end
    lies above the least upper end of its clip (over starts not possibly at distance 0) cannot be the
    clip's nearest; the others are the candidates. Per step of a synthesis of ``speech`` (today's
    search chooses the path; ``steps`` of its steps, spread over it) it prints, in float64: how many
    clips' nearest start the pass decides, the candidates' share of the starts, the interval's width
    at the nearest start over its distance, how many float32 rows today's 8-bit tier then still reads
    among the candidates (vs on every start, as today), and how many clips the skip rule of
    ``docs/METHOD.md`` ("Exact arithmetic") would still have to read with the deciding clips known
    and the audio known exactly at every candidate (or at every start the 8-bit tier leaves open);
    then the bytes a step as each design would read them (104 a frame of the 8-bit copy, 384 a float32
    pose row, 448 an audio row).
    Timings, measured in one run: today's scan of a step, the same scan restricted to the candidates
    (d = 16, int8; the pass itself not counted), the same scan given each clip's nearest start only
    (what any first pass that decided every clip would leave) and given the starts today's 8-bit
    tier leaves open (what its float32 rows add to that), a float32 product over the d = 16
    coordinates (a stand-in for the pass) and one float32 matrix-vector product over the pose matrix.
    """
    from concurrent.futures import ThreadPoolExecutor

    from gesturekit.database import MatchingDatabase
    from gesturekit.datasets.synthetic import generate_demo_take
    from gesturekit.search.admissible import base_starts
    from gesturekit.search.reduced import clip_bounds, quantise_query
    from gesturekit.search.threads import single_threaded_blas
    from gesturekit.synthesis import synthesize, synthesizer_for

    db = MatchingDatabase.load(path)
    if speech is None:
        audio, said = generate_demo_take(seconds=60.0, seed=7, name="query")[0].audio, "60 s of generated demo speech"
    else:
        audio, said = speech, f"{speech.name}"
    res = synthesize(audio, db=db)  # today's search: the path whose steps are measured
    chosen, plan = res.search, res.plan
    N, width = chosen.config.segment, chosen.config.table_width
    P3, F3 = np.asarray(db.P), np.asarray(db.F)
    M, T, D = P3.shape
    adm_all = base_starts(np.asarray(db.valid), N, plan.exclude)
    index = synthesizer_for(db).index
    red = index.reduced()
    dmax = max(LOWD_DIMS)
    # the basis, from the deviations of up to 4096 clips spread over the database
    sample = np.unique(np.linspace(0, M - 1, min(M, 4096)).astype(int))
    Xs = np.asarray(P3[sample], np.float64)
    Xs -= Xs.mean(axis=1, keepdims=True)
    Z = Xs[adm_all[sample]]
    w, V = np.linalg.eigh(Z.T @ Z)
    w, V = w[::-1], V[:, ::-1][:, :dmax]
    kept = np.cumsum(w) / w.sum()
    chunk = 2048
    Y = np.empty((M, T, dmax), np.float32)
    resid = np.empty((len(LOWD_DIMS), M, T), np.float32)
    lost32 = np.empty((len(LOWD_DIMS), M, T), np.float32)  # what storing y in float32 loses
    slack = np.empty((M, T), np.float32)  # bounds the rounding of r: 2e-6 |p - c_m|
    centre = np.empty((M, D))
    for c0 in range(0, M, chunk):
        X = np.asarray(P3[c0 : c0 + chunk], np.float64)
        cm = X.mean(axis=1)
        X -= cm[:, None]
        y = X @ V
        y32 = y.astype(np.float32)
        Y[c0 : c0 + chunk], centre[c0 : c0 + chunk] = y32, cm
        x2, cum = (X**2).sum(-1), np.cumsum(y**2, axis=-1)
        # the float64 cancellation in |x|^2 - |y|^2 and the float32 storage of r
        slack[c0 : c0 + chunk] = 2e-6 * np.sqrt(x2)
        for k, d in enumerate(LOWD_DIMS):
            resid[k, c0 : c0 + chunk] = np.sqrt(np.maximum(x2 - cum[..., d - 1], 0.0))
            lost32[k, c0 : c0 + chunk] = np.linalg.norm(y[..., :d] - y32[..., :d], axis=-1) * (1 + 1e-6)
    variants = [(d, s) for d in LOWD_DIMS for s in LOWD_CODES]
    picked = np.unique(np.linspace(1, chosen.clip.size - 1, steps).round().astype(int))
    print(
        f"low-d first pass on {path}: {M} clips x {T} frames; {said}, {len(picked)} of its {chosen.clip.size} steps; "
        f"{width} rows listed; basis of {len(sample)} clips' deviations, variance kept "
        + ", ".join(f"d={d} {kept[d - 1]:.1%}" for d in LOWD_DIMS)
    )
    stats: dict = {v: [] for v in variants}
    today: list = []
    timed = []
    for i in picked:
        q = np.asarray(P3[chosen.clip[i - 1], chosen.start[i - 1] + N - 1], np.float64)
        f = np.asarray(plan.query[i * N], np.float64)
        fn = f / np.linalg.norm(f)
        qc = quantise_query(q.astype(np.float32))
        d_near, a_near, s_near = np.full(M, np.inf), np.full(M, np.inf), np.zeros(M, np.int64)
        open_today = np.zeros(M, np.int64)
        per = {
            v: {k: np.zeros(M) for k in ("decided", "cand", "lb", "audio", "open", "lb8", "audio8", "width")}
            for v in variants
        }
        cand16, open16 = np.zeros((M, T), bool), np.zeros((M, T), bool)
        for c0 in range(0, M, chunk):
            c1 = min(M, c0 + chunk)
            n, rows = c1 - c0, np.arange(c1 - c0)
            adm = adm_all[c0:c1]
            X = np.asarray(P3[c0:c1], np.float64)
            d2 = ((X - q) ** 2).sum(-1)
            Fa = np.asarray(F3[c0:c1], np.float64)
            norm = np.linalg.norm(Fa, axis=-1)
            with np.errstate(invalid="ignore", divide="ignore"):
                cos = np.where(norm > 0, 1.0 - (Fa @ fn) / norm, 1.0)
            d2n = np.where(adm & (d2 > 0), d2, np.inf)
            s = d2n.argmin(axis=1)
            d_near[c0:c1], s_near[c0:c1] = d2n[rows, s], s
            a_near[c0:c1] = np.where(np.isfinite(d_near[c0:c1]), cos[rows, s], np.inf)
            # today's 8-bit estimates and bound, as the scan makes them
            dot = (red.codes[c0:c1].reshape(-1, D).astype(np.int32) @ qc.codes.astype(np.int32)).reshape(n, T)
            centred = ((q - red.centre[c0:c1].astype(np.float64)) ** 2).sum(-1)
            est = red.kappa[c0:c1] + red.coef[c0:c1] * (np.float32(qc.scale) * dot.astype(np.float32))
            est = np.where(adm, est.astype(np.float64) + centred[:, None], np.inf)
            err = clip_bounds(red.stats[c0:c1], centred, qc, D)
            left_today = _open_starts(est, err, adm)
            open16[c0:c1] = left_today
            left = left_today.sum(axis=1)
            open_today[c0:c1] = np.where(left > 1, left, 0)
            Qc = q - centre[c0:c1]
            Pq = Qc @ V
            for k, d in enumerate(LOWD_DIMS):
                a = np.linalg.norm(Qc - Pq[:, :d] @ V[:, :d].T, axis=-1)[:, None]
                r = resid[k, c0:c1]
                # |a - r| and a + r as the exact r could make them
                apart = np.maximum(np.abs(a - r) - slack[c0:c1] - 1e-12 * a, 0.0)
                joint = a * (1 + 1e-12) + r + slack[c0:c1]
                for storage, top in LOWD_CODES.items():
                    y = Y[c0:c1, :, :d].astype(np.float64)
                    if top:
                        scale = np.abs(y).max(axis=-1, keepdims=True) / top
                        scale[scale == 0] = 1.0
                        yq = np.clip(np.rint(y / scale), -top, top) * scale
                        e = np.linalg.norm(y - yq, axis=-1) * (1 + 1e-9) + lost32[k, c0:c1]
                    else:
                        yq, e = y, lost32[k, c0:c1]
                    g = np.linalg.norm(Pq[:, None, :d] - yq, axis=-1)
                    lo = np.where(adm, np.maximum(g - e, 0.0) ** 2 + apart**2, np.inf)
                    hi = np.where(adm, (g + e) ** 2 + joint**2, np.inf)
                    least_hi = np.where(lo > 0, hi, np.inf).min(axis=1)[:, None]
                    cand = adm & ((lo <= least_hi) | ~np.isfinite(least_hi))
                    hit = np.isfinite(d_near[c0:c1])
                    assert cand[rows[hit], s[hit]].all(), "a clip's nearest start fell outside its candidates"
                    left8 = _open_starts(est, err, cand)
                    st = per[(d, storage)]
                    st["decided"][c0:c1] = (cand.sum(1) == 1) & np.isfinite(least_hi[:, 0])
                    st["cand"][c0:c1] = cand.sum(1)
                    st["lb"][c0:c1] = lo.min(axis=1)
                    st["audio"][c0:c1] = np.where(cand, cos, np.inf).min(axis=1)
                    st["open"][c0:c1] = np.where(left8.sum(1) > 1, left8.sum(1), 0)
                    st["lb8"][c0:c1] = np.where(left8, np.maximum(lo, est - err[:, None]), np.inf).min(axis=1)
                    st["audio8"][c0:c1] = np.where(left8, cos, np.inf).min(axis=1)
                    with np.errstate(invalid="ignore", divide="ignore"):
                        st["width"][c0:c1] = (hi - lo)[rows, s] / d_near[c0:c1]
                    if (d, storage) == (16, "int8"):
                        cand16[c0:c1] = cand
        alive = np.isfinite(d_near)
        idx = np.flatnonzero(alive)
        pose_rank = np.empty(idx.size, np.int64)
        pose_rank[np.lexsort((idx, d_near[idx]))] = np.arange(idx.size)
        audio_rank = np.empty(idx.size, np.int64)
        audio_rank[np.lexsort((idx, a_near[idx]))] = np.arange(idx.size)
        combined = pose_rank + audio_rank
        listed = combined <= np.sort(combined)[min(width, idx.size) - 1]
        d_top, a_top = d_near[idx][listed].max(), a_near[idx][listed].max()
        n_alive, frames = int(alive.sum()), M * T
        today.append(
            {
                "open": float(np.mean(open_today[alive] > 0)),
                "rows": int(open_today.sum()),
                "bytes": 104 * frames + 384 * int(open_today.sum()) + 832 * n_alive,
            }
        )
        for v, st in per.items():
            read = alive & ~((st["lb"] > d_top) & (st["audio"] > a_top))
            read8 = alive & ~((st["lb8"] > d_top) & (st["audio8"] > a_top))
            n_cand = int(st["cand"][alive].sum())
            a_rows = 104 * n_cand + 384 * int(st["open"].sum()) + 832 * n_alive
            c_rows = 104 * n_cand + 448 * int(np.where(st["open"] > 0, st["open"], 1)[alive & ~read8].sum())
            c_rows += 384 * int(st["open"][read8].sum()) + 832 * int(read8.sum())
            stats[v].append(
                {
                    "decided": float(st["decided"][alive].mean()),
                    "cand": n_cand / int(adm_all.sum()),
                    "width": float(np.median(st["width"][alive])),
                    "rows": int(st["open"].sum()),
                    "left": float(np.where(st["open"] > 0, st["open"], 1)[alive].mean()),
                    "read": float(read[alive].mean()),
                    "read8": float(read8[alive].mean()),
                    "bytes_a": lowd_bytes(*v) * frames + a_rows,
                    "bytes_c": lowd_bytes(*v) * frames + c_rows,
                }
            )
        s16 = stats[(16, "int8")][-1]
        print(
            f"  step {i}: deciding clips up to rank {pose_rank[listed].max()} (pose), {audio_rank[listed].max()} "
            f"(audio); today the 8-bit tier leaves {today[-1]['open']:.0%} of clips open, {today[-1]['rows']} "
            f"float32 rows; d=16 int8: nearest start decided for {s16['decided']:.1%} of clips, candidates "
            f"{s16['cand']:.1%} of starts, then {s16['rows']} float32 rows; clips the skip rule must read "
            f"{s16['read']:.1%} (audio known at the candidates), {s16['read8']:.1%} (at the starts the 8-bit tier "
            f"leaves)",
            flush=True,
        )
        if len(timed) < 3:
            oracle = np.zeros((M, T), bool)
            oracle[np.flatnonzero(alive), s_near[alive]] = True
            timed.append((q.astype(np.float32), plan.query[i * N], cand16.ravel(), open16.ravel(), oracle.ravel()))

    def med(xs: list, f: str = "{:.1%}") -> str:
        x = np.asarray(xs, float)
        return (f + " [" + f + ".." + f + "]").format(np.median(x), x.min(), x.max())

    print(f"\n  per step, median [min..max] over {len(picked)} steps:")
    print(
        f"  today: the 8-bit tier leaves {med([t['open'] for t in today])} of clips open and "
        f"{med([t['rows'] for t in today], '{:.0f}')} float32 rows to read; "
        f"{med([t['bytes'] / 1e6 for t in today], '{:.0f}')} MB read"
    )
    base = np.asarray([t["bytes"] for t in today], float)
    for v in variants:
        x = stats[v]

        def get(k: str, x: list = x) -> list:
            return [s[k] for s in x]

        mb_a, mb_c = np.asarray(get("bytes_a")), np.asarray(get("bytes_c"))
        print(
            f"  d={v[0]:2d} {v[1]:7s} ({lowd_bytes(*v):g} B a frame): nearest start decided {med(get('decided'))}, "
            f"candidates {med(get('cand'))} of starts, width/distance {med(get('width'), '{:.3f}')}; the 8-bit "
            f"tier on the candidates leaves {med(get('left'), '{:.1f}')} starts a clip, {med(get('rows'), '{:.0f}')} "
            f"float32 rows; MB read {med(mb_a / 1e6, '{:.0f}')} = {np.median(base / mb_a):.2f}x fewer than today. "
            f"With the skip rule, clips to read {med(get('read'))} (audio known at the candidates), "
            f"{med(get('read8'))} (at the starts the 8-bit tier leaves; then MB read {med(mb_c / 1e6, '{:.0f}')} = "
            f"{np.median(base / mb_c):.2f}x fewer)"
        )

    # timings, in one run: each of today's scans and its variants bracketed by matrix-vector products
    cache: dict = {}
    _, key = index._admissible(cache, N, chosen.config.mask_rule, -1, None, plan.exclude)
    bias = index._bias(cache, key)
    P2 = index._P2
    gq = np.array(P2[min(12345, P2.shape[0] - 1)], np.float32)
    out = np.empty(P2.shape[0], np.float32)
    Y16 = np.ascontiguousarray(Y[..., :16]).reshape(-1, 16)
    out16 = np.empty(Y16.shape[0], np.float32)
    pool = ThreadPoolExecutor(index._workers) if index._workers > 1 else None
    names = ("today", "candidates", "open", "nearest", "pass")
    times: dict = {k: [] for k in names}
    gemvs: list = []
    scratch: dict = {}
    try:
        for _ in range(runs):
            for q32, f32, cand, left, oracle in timed:
                g0 = best_of(lambda: np.dot(P2, gq, out=out), 3)
                t_pass = best_of(lambda: np.dot(Y16, gq[:16], out=out16), 3)
                time.sleep(BLAS_IDLE)
                biases = [bias] + [np.where(x, bias, np.inf) for x in (cand, left, oracle)]
                with single_threaded_blas():
                    t = [_timed_scan(index, q32, f32, b, pool, scratch) for b in biases]
                g1 = best_of(lambda: np.dot(P2, gq, out=out), 3)
                gemvs.append(0.5 * (g0 + g1))
                for k, x in zip(names, (*t, t_pass)):
                    times[k].append(x / gemvs[-1])
    finally:
        if pool is not None:
            pool.shutdown()
    r = {k: float(np.median(v)) for k, v in times.items()}
    new = r["candidates"] + r["pass"]
    print(
        f"\n  timed ({runs} runs of {len(timed)} steps, each bracketed by products), as multiples of one float32 "
        f"matrix-vector product over the pose matrix ({float(np.median(gemvs)) * 1e3:.1f} ms), medians: today's scan "
        f"of a step {r['today']:.2f}x; the same scan on the d=16 int8 candidates only {r['candidates']:.2f}x, plus "
        f"the pass (a float32 product over the 16 coordinates, 64 B a frame; int8 codes would read 32) "
        f"{r['pass']:.2f}x: {new:.2f}x, {r['today'] / new:.2f} times today's speed; given each clip's nearest start "
        f"only (any first pass that decided every clip) {r['nearest']:.2f}x, given the starts today's 8-bit tier "
        f"leaves (their float32 rows read) {r['open']:.2f}x; load average "
        + " ".join(f"{x:.1f}" for x in os.getloadavg())
    )


def tile(src: Path, dst: Path, hours: float) -> Path:
    """``src`` (without its audio and overlapping cut) repeated to at least ``hours`` of clips at ``dst``."""
    from gesturekit.database.folder import CLIP_ARRAYS

    meta = json.loads((src / "database.json").read_text())
    ct = np.load(src / "clip_take.npy", allow_pickle=False)
    M, n_takes = ct.shape[0], len(meta["takes"])
    reps = max(1, math.ceil(hours * 3600 * 15 / (M * meta["build"]["clip_frames"])))
    dst.mkdir()
    for k in CLIP_ARRAYS + ("clip_take", "clip_start"):
        a = np.load(src / f"{k}.npy", mmap_mode="r", allow_pickle=False)
        out = np.lib.format.open_memmap(dst / f"{k}.npy", mode="w+", dtype=a.dtype, shape=(M * reps,) + a.shape[1:])
        for r in range(reps):
            out[r * M : (r + 1) * M] = a + r * n_takes if k == "clip_take" else a
        out.flush()
        del out
    shutil.copy(src / "stats.npz", dst / "stats.npz")
    takes = []
    for r in range(reps):
        for t in meta["takes"]:
            entry = {k: v for k, v in t.items() if k != "audio_size"}
            takes.append({**entry, "name": f"{t['name']}~{r}", "first_clip": t["first_clip"] + r * M})
            takes[-1].update(audio_offset=0, audio_samples=0)
    meta.update(takes=takes, counts={"clips": M * reps, "takes": len(takes)})
    meta["build"].update(store_audio=False, overlap_stride=None)
    meta.pop("audio", None)
    (dst / "database.json").write_text(json.dumps(meta))
    return dst


def _fmt_bytes(n: float) -> str:
    return f"{n / 2**30:.2f} GiB" if abs(n) >= 2**30 else f"{n / 2**20:.0f} MiB"


def print_search(label: str, s: dict) -> None:
    print(
        f"  {label}: {s['frames'] / 1e6:.2f} M frames; opened in {s['open'] * 1e3:.0f} ms; "
        f"step {s['step'] * 1e3:.1f} ms vs mat-vec {s['gemv'] * 1e3:.1f} ms = {s['ratio']:.2f}x (target <= 1.0x); "
        f"60 s of speech {s['e2e']:.2f} s (target <= 2 s at 100 h) = {s['e2e_ratio']:.2f}x 113 mat-vecs "
        f"(first call, index prepared: {s['e2e_first']:.2f} s); the scan read the {s.get('copy', '8-bit copy')}"
    )
    print(
        f"    memory beyond the database during the first synthesis: numpy {_fmt_bytes(s['traced'])}, "
        f"anonymous RSS {_fmt_bytes(s['anon'])} = {max(s['traced'], s['anon']) / s['searched']:.1%} of the "
        f"searched arrays P, F, valid ({_fmt_bytes(s['searched'])}), "
        f"{max(s['traced'], s['anon']) / s['folder']:.1%} of the folder (target < 25 %, the scan's pose copy included)"
    )


def project(a: dict, b: dict, hours: float = 100.0) -> None:
    """Print each figure at ``hours`` on the line through its values at the two measured sizes."""
    print(f"\n[projection to {hours:g} h from the slope between {a['hours']:.2f} h and {b['hours']:.2f} h]")

    def at(get, clamp: bool = False) -> float:
        slope = (get(b) - get(a)) / (b["hours"] - a["hours"])
        if slope < 0:  # noise larger than the difference: nothing grows measurably, or the sizes are too small
            return get(b) if clamp else float("nan")
        return get(b) + slope * (hours - b["hours"])

    for w in sorted({int(k[5:]) for k in b if k.startswith("build")}):
        t = at(lambda r, w=w: r[f"build{w}"])
        print(
            f"  build, {w} worker{'s' * (w > 1)}: {t / 3600:.2f} h = {hours * 3600 / t:.0f}x real time; "
            f"peak RSS {_fmt_bytes(at(lambda r, w=w: r[f'rss{w}'], clamp=True))}"
        )
    extra = at(lambda r: r["search"]["traced"], clamp=True)
    searched = at(lambda r: r["search"]["searched"])
    print(
        f"  on disk {_fmt_bytes(at(lambda r: r['size']))}; memory beyond the database during a synthesis "
        f"(numpy's allocations) {_fmt_bytes(extra)} = {extra / searched:.1%} of P, F, valid ({_fmt_bytes(searched)})"
    )
    if a["search"]["searched"] < 2**28:  # the mat-vec still runs from the processor's caches
        print("  search: the smaller size is too small to project from (under 256 MiB of P, F); see --tile-hours")
        return
    step, e2e, gemv = (at(lambda r, k=k: r["search"][k]) for k in ("step", "e2e", "gemv"))
    print(
        f"  search step {step * 1e3:.0f} ms vs mat-vec {gemv * 1e3:.0f} ms = {step / gemv:.2f}x; "
        f"60 s of speech {e2e:.1f} s = {e2e / (STEPS_60S * gemv):.2f}x 113 mat-vecs "
        "(nan: no slope could be measured)"
    )


def same_bytes(x: Path, y: Path) -> bool:
    """Whether two database folders hold the same files with the same bytes."""
    fx = sorted(p.relative_to(x) for p in x.rglob("*") if p.is_file())
    if fx != sorted(p.relative_to(y) for p in y.rglob("*") if p.is_file()):
        return False
    return all(filecmp.cmp(x / f, y / f, shallow=False) for f in fx)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--hours", type=float, default=1.0, help="hours of takes (the smaller size is half)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="workers of the parallel build")
    ap.add_argument("--take-seconds", type=float, default=120.0, help="length of each take")
    ap.add_argument("--tile-hours", type=float, help="also search the database repeated to this many hours")
    ap.add_argument("--runs", type=int, default=5, help="pairs of (search, mat-vec) timed per size")
    ap.add_argument("--keep", action="store_true", help="keep the takes and databases (the folder is printed)")
    ap.add_argument("--dir", help="where to make the temporary folder (default: the system's)")
    ap.add_argument("--search-only", metavar="FOLDER", help="only the search figures of this database folder")
    ap.add_argument("--device", help="with --search-only: also the search with its scan on this torch device")
    ap.add_argument("--bounds", metavar="FOLDER", help="only what bounds could leave unread in this database")
    ap.add_argument("--block", type=int, default=8, help="starts per block for --bounds")
    ap.add_argument("--lowd", metavar="FOLDER", help="only what a low-d first pass could decide in this database")
    ap.add_argument("--speech", type=Path, default=SPEECH, help="speech for --lowd (default: BEAT from ../shared)")
    ap.add_argument("--steps", type=int, default=9, help="steps of the speech --lowd measures")
    args = ap.parse_args(argv)
    if args.lowd:
        print(machine())
        speech = args.speech if args.speech is not None and args.speech.exists() else None
        if speech is None:
            print(f"(no speech file at {args.speech}: generated demo speech instead)")
        lowd_figures(Path(args.lowd), speech, steps=args.steps, runs=args.runs)
        return
    if args.bounds:
        print(machine())
        bound_figures(Path(args.bounds), block=args.block)
        return
    if args.search_only:
        print(machine())
        print_search(f"search of {args.search_only}", search_figures(Path(args.search_only), args.runs))
        if args.device:
            device_figures(Path(args.search_only), args.device, args.runs)
        return
    if not args.hours > 0 or args.workers < 1:
        ap.error("--hours must be positive and --workers at least 1")

    from gesturekit.workspace import build_database

    parallel = "workers" in inspect.signature(build_database).parameters
    print(machine())
    root = Path(tempfile.mkdtemp(prefix="gesturekit-scale-", dir=args.dir))
    try:
        t0 = time.perf_counter()
        half, full, s_half, s_full = write_takes(root, args.hours, args.take_seconds, args.workers)
        jmap = joint_map(root)
        print(
            f"takes: {len(list(full.glob('*.bvh')))} of {args.take_seconds:g} s as BVH ({FPS_BVH:g} fps) + wav "
            f"({_fmt_bytes(folder_bytes(full))}), written in {time.perf_counter() - t0:.0f} s to {root}"
        )
        if not parallel:
            print("  (this build takes no workers: the build with all workers is not run)")
        rows = []
        for label, folder, secs in (("half", half, s_half), ("all", full, s_full)):
            hours = secs / 3600
            print(f"\n[{hours:.2f} h: {folder.name}]")
            row: dict = {"hours": hours}
            for w in [1, args.workers] if parallel and args.workers > 1 else [1]:
                out = root / f"db-{label}-{w}"
                b = build(folder, out, jmap, w)
                row[f"build{w}"], row[f"rss{w}"] = b["seconds"], max(b["rss"], b["rss_workers"])
                print(
                    f"  build, {w} worker{'s' * (w > 1)}: {b['seconds']:.1f} s = {secs / b['seconds']:.0f}x real time; "
                    f"peak RSS {_fmt_bytes(b['rss'])}"
                    + (f" (largest worker {_fmt_bytes(b['rss_workers'])})" if w > 1 else "")
                    + "; "
                    f"{b['clips']} clips"
                    + (f"; the same bytes as with 1 worker: {same_bytes(root / f'db-{label}-1', out)}" if w > 1 else "")
                )
                if w > 1:
                    shutil.rmtree(out)
            db_path = root / f"db-{label}-1"
            size, audio = folder_bytes(db_path), (db_path / "audio.npy").stat().st_size
            row["size"] = size
            other = f"; stored otherwise: {audio_options(db_path)}" if label == "all" else ""
            print(f"  on disk {_fmt_bytes(size)}, of which audio {_fmt_bytes(audio)} ({audio / size:.0%}){other}")
            row["search"] = search_figures(db_path, args.runs)
            print_search("search", row["search"])
            rows.append(row)

        project(*rows)
        if args.tile_hours:
            t0 = time.perf_counter()
            tiled = tile(root / "db-all-1", root / "db-tiled", args.tile_hours)
            print(
                f"\n[{args.tile_hours:g} h: the {rows[-1]['hours']:.2f} h database repeated, written in "
                f"{time.perf_counter() - t0:.0f} s, {_fmt_bytes(folder_bytes(tiled))} without audio]"
            )
            print_search("search", search_figures(tiled, args.runs))
    finally:
        if args.keep:
            print(f"\nkept: {root}")
        else:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
