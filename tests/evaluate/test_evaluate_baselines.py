"""The baseline systems against literal loops of their definitions, and running every system."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.blend import keep_slow
from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.errors import ConfigError
from gesturekit.evaluate.baselines import (
    SystemUnavailable,
    admissible_windows,
    audio_nearest_segments,
    parse_systems,
    pose_nearest_segments,
    random_segments,
    run_system,
)
from gesturekit.motion import Motion
from gesturekit.synthesis import SynthesisConfig
from tests.conftest import make_take


def _literal_admissible(valid, step, exclude, mask, rule):
    M, T = valid.shape
    out = np.zeros((M, T), bool)
    for m in range(M):
        for s in range(T - step + 1):
            ok = valid[m, s]
            if exclude is not None:
                ok &= not exclude[m, s : s + step].any()
            if mask is not None:
                ok &= (mask[m, s] and mask[m, s + step - 1]) if rule == "ends" else mask[m, s : s + step].all()
            out[m, s] = ok
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 6), st.sampled_from(["ends", "all"]))
def test_admissible_windows_equal_the_definition(seed, step, rule):
    rng = np.random.default_rng(seed)
    valid, exclude, mask = rng.random((3, 4, 10)) < [[[0.8]], [[0.15]], [[0.7]]]
    got = admissible_windows(valid, segment=step, exclude=exclude, mask=mask, mask_rule=rule)
    np.testing.assert_array_equal(got, _literal_admissible(valid, step, exclude, mask, rule))


def _arrays(seed, M=5, T=16, D=4):
    rng = np.random.default_rng(seed)
    P = rng.normal(size=(M, T, D)).astype(np.float32)
    F = rng.normal(size=(M, T, 6)).astype(np.float32)
    valid = rng.random((M, T)) < 0.9
    return P, F, valid


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_audio_nearest_equals_a_literal_loop(seed):
    P, F, valid = _arrays(seed)
    rng = np.random.default_rng(seed + 1)
    q = rng.normal(size=(21, 6)).astype(np.float32)
    frames, relaxed = audio_nearest_segments(F, valid, q, segment=4)
    adm = _literal_admissible(valid, 4, None, None, "ends")
    for i in range(-(-21 // 4)):
        f = q[4 * i].astype(np.float64)
        best, arg = np.inf, None
        for m in range(F.shape[0]):
            for s in range(F.shape[1]):
                if adm[m, s]:
                    r = F[m, s].astype(np.float64)
                    d = 1 - r @ f / (np.linalg.norm(r) * np.linalg.norm(f))
                    if d < best - 1e-12:
                        best, arg = d, (m, s)
        assert tuple(frames[4 * i]) == arg
    assert not relaxed.any()
    assert frames.shape == (21, 2)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_pose_nearest_equals_a_literal_loop(seed):
    P, F, valid = _arrays(seed)
    frames, _ = pose_nearest_segments(P, valid, n_frames=18, segment=4, init_pose=P[0, 0])
    adm = _literal_admissible(valid, 4, None, None, "ends")
    p = P[0, 0].astype(np.float64)
    for i in range(-(-18 // 4)):
        best, arg = np.inf, None
        for m in range(P.shape[0]):
            for s in range(P.shape[1]):
                d = np.sum((P[m, s].astype(np.float64) - p) ** 2)
                if adm[m, s] and 0 < d < best:
                    best, arg = d, (m, s)
        assert tuple(frames[4 * i]) == arg
        # the window's frames follow one another in the clip
        seg = frames[4 * i : 4 * i + 4]
        assert np.all(seg[:, 0] == arg[0]) and np.array_equal(seg[:, 1], arg[1] + np.arange(len(seg)))
        p = P[arg[0], arg[1] + 3].astype(np.float64)


def test_random_segments_are_admissible_seeded_and_relax_impossible_controls():
    P, F, valid = _arrays(3, M=6, T=20)
    exclude = np.zeros_like(valid)
    exclude[:3] = True
    masks = np.stack([np.ones_like(valid), np.zeros_like(valid)])
    step_mask = np.array([0, 1, -1, 0, 1])
    frames, relaxed = random_segments(
        valid, n_frames=40, segment=8, seed=5, exclude=exclude, masks=masks, step_mask_index=step_mask
    )
    assert relaxed.tolist() == [False, True, False, False, True]
    adm = _literal_admissible(valid, 8, exclude, None, "ends")
    for i in range(5):
        c, s = frames[8 * i]
        assert adm[c, s] and c >= 3
    again, _ = random_segments(
        valid, n_frames=40, segment=8, seed=5, exclude=exclude, masks=masks, step_mask_index=step_mask
    )
    other, _ = random_segments(
        valid, n_frames=40, segment=8, seed=6, exclude=exclude, masks=masks, step_mask_index=step_mask
    )
    assert np.array_equal(frames, again) and not np.array_equal(frames, other)
    with pytest.raises(ConfigError, match="no admissible"):
        random_segments(valid, n_frames=8, segment=8, exclude=np.ones_like(valid))


def test_parse_systems():
    assert parse_systems("gt, knn,knn,random") == ("gt", "knn", "random")
    with pytest.raises(ConfigError, match="unknown system"):
        parse_systems("gt,mogflow")
    with pytest.raises(ConfigError, match="at least one"):
        parse_systems(",")


@pytest.fixture(scope="module")
def small_db():
    takes = [make_take(30.0, seed=s, name=f"t{s}") for s in range(3)]
    return MatchingDatabase.build(takes, config=BuildConfig(store_audio=False))


class _ScaleRefiner:
    """A stand-in refiner: records what it was given and scales the motion."""

    def __init__(self):
        self.calls = []

    def check_database(self, db):
        """The real refiner refuses a database of another layout; this one takes any."""

    def refine_motion(self, motion, audio_features):
        self.calls.append((motion.n_frames, audio_features.shape))
        return Motion(motion.positions * 0.5, motion.fps)


@pytest.mark.slow
def test_every_system_runs_and_keeps_out_of_excluded_takes(small_db):
    audio = make_take(6.0, seed=9).audio
    cfg = SynthesisConfig(exclude_takes=("t0",), seed=2)
    gt = Motion(np.zeros((90, 55, 3), np.float32), 15)
    table = small_db.clips_table()
    refiner = _ScaleRefiner()
    outs = {}
    for system in ("gt", "random", "audio-only", "pose-only", "knn", "knn+cgan"):
        out = run_system(system, db=small_db, audio=audio, config=cfg, gt=gt, refiner=refiner)
        assert out.motion.n_frames == 90
        assert out.boundaries.tolist() == list(range(8, 90, 8))
        outs[system] = out
    knn = run_system("knn", db=small_db, audio=audio, config=cfg)
    # the refiner's output, with the k-NN motion's content below 2 Hz kept (the synthesis default)
    want = keep_slow(0.5 * knn.motion.flat(), knn.motion.flat(), 2.0).reshape(-1, 55, 3)
    np.testing.assert_allclose(outs["knn+cgan"].motion.positions, want, atol=1e-6)
    assert refiner.calls == [(90, (90, 28))]
    G = np.asarray(small_db.G).reshape(-1, 165)
    used_t0 = G[np.asarray(table["take"] == "t0").repeat(small_db.clip_frames)]
    for system in ("random", "audio-only", "pose-only"):
        flat = outs[system].motion.flat()
        # no output frame is a frame of the excluded take
        assert not any((np.abs(used_t0 - row).max(axis=1) == 0).any() for row in flat[::8])


def test_unavailable_systems_say_why(small_db):
    audio = make_take(3.0, seed=9).audio
    with pytest.raises(SystemUnavailable, match="refiner"):
        run_system("knn+cgan", db=small_db, audio=audio)
    with pytest.raises(SystemUnavailable, match="recorded motion"):
        run_system("gt", db=small_db, audio=audio)
