"""One search step explained: equal to the search, decision for decision, for every clip; its figures."""

from __future__ import annotations

import warnings
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.control import ATTRIBUTE_NAMES, CONSTRAINTS, frame_attributes, parse_control
from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.errors import ConfigError, GestureKitWarning
from gesturekit.evaluate import metrics
from gesturekit.features import LAYOUT
from gesturekit.motion import Motion
from gesturekit.search import SearchConfig, search
from gesturekit.search.reference import cosine_distance, pose_sqdist, window_admissible
from gesturekit.synthesis import SynthesisConfig, synthesize
from gesturekit.viz.walkthrough import (
    constraints_table,
    control_statistics,
    explain_step,
    explain_synthesis_step,
    feature_blocks,
    feature_figure,
    motion_measures,
    rankings_figure,
    step_inputs,
    synthesis_table,
)
from tests.conftest import make_take


def _db(seed: int, *, M: int = 7, T: int = 16, D: int = 6, A: int = 5, levels: int = 0) -> SimpleNamespace:
    """Random features; with ``levels`` > 0 they take few values, so distances tie often."""
    rng = np.random.default_rng(seed)
    if levels:
        P = rng.integers(-levels, levels + 1, size=(M, T, D)).astype(np.float32)
        F = rng.integers(-levels, levels + 1, size=(M, T, A)).astype(np.float32)
    else:
        P = rng.normal(size=(M, T, D)).astype(np.float32)
        F = rng.normal(size=(M, T, A)).astype(np.float32)
    valid = rng.random((M, T)) < 0.85
    return SimpleNamespace(P=P, F=F, valid=valid)


def _check_step(db, res, query, i, *, N, k, mask, exclude, rule):
    pose = res.init_pose if i == 0 else db.P[res.clip[i - 1], res.start[i - 1] + N - 1]
    e = explain_step(db, query, pose, t=i * N, segment=N, k=k, mask=mask, exclude=exclude, mask_rule=rule)
    assert (e.clip, e.start, e.position) == (res.clip[i], res.start[i], res.position[i])
    assert e.relaxed == bool(res.relaxed[i])
    assert e.n_survivors == res.n_candidates[i]
    top = e.ranking().iloc[: res.cand_clip.shape[1]]
    w = len(top)
    np.testing.assert_array_equal(top["clip"], res.cand_clip[i, :w])
    np.testing.assert_array_equal(top["start"], res.cand_start[i, :w])
    np.testing.assert_array_equal(top["pose_rank"], res.cand_pose_rank[i, :w])
    np.testing.assert_array_equal(top["audio_rank"], res.cand_audio_rank[i, :w])
    np.testing.assert_array_equal(top["combined"], res.cand_combined[i, :w])
    np.testing.assert_array_equal(top["pose_dist"], res.cand_pose_dist[i, :w])  # bit for bit
    np.testing.assert_array_equal(top["audio_dist"], res.cand_audio_dist[i, :w])
    np.testing.assert_array_equal(e.next_pose, db.P[e.clip, e.start + N - 1])
    return e


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 10_000),
    k=st.integers(0, 8),
    N=st.sampled_from([1, 3, 4, 8]),
    rule=st.sampled_from(["ends", "all"]),
    levels=st.sampled_from([0, 1, 2]),
    controlled=st.booleans(),
    excluded=st.booleans(),
)
def test_every_step_equals_the_search(seed, k, N, rule, levels, controlled, excluded):
    db = _db(seed, levels=levels)
    rng = np.random.default_rng(seed + 1)
    T_out = 3 * N + 2
    query = (rng.integers(-2, 3, size=(T_out, 5)) if levels else rng.normal(size=(T_out, 5))).astype(np.float32)
    n_steps = -(-T_out // N)
    masks = step_mask = exclude = None
    if controlled:
        # a rare constraint, so some steps must relax
        masks = np.stack([rng.random(db.valid.shape) < 0.5, rng.random(db.valid.shape) < 0.02])
        step_mask = rng.integers(-1, 2, size=n_steps)
    if excluded:
        exclude = np.zeros(db.valid.shape, bool)
        exclude[0] = True
        exclude[1, 4:9] = True
    cfg = SearchConfig(k=k, segment=N, record=6, seed=seed, mask_rule=rule)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GestureKitWarning)
        try:
            res = search(
                db.P, db.F, db.valid, query, config=cfg, masks=masks, step_mask_index=step_mask, exclude=exclude
            )
        except ConfigError:
            return  # nothing admissible at all: the explanation raises too (tested below)
    for i in range(res.n_steps):
        mask = None if masks is None or step_mask[i] < 0 else masks[step_mask[i]]
        _check_step(db, res, query, i, N=N, k=k, mask=mask, exclude=exclude, rule=rule)


def test_table_holds_every_clip_with_the_definitions_of_the_reference():
    db = _db(3, M=9)
    q = np.random.default_rng(4).normal(size=(10, 5)).astype(np.float32)
    pose = db.P[2, 5]
    e = explain_step(db, q, pose, t=2, segment=4, k=1)
    assert list(e.table["clip"]) == list(range(9))
    for row in e.table.itertuples():
        adm = [s for s in range(16) if window_admissible(row.clip, s, 4, valid=db.valid)]
        assert row.admissible == len(adm)
        d2 = {s: pose_sqdist(db.P[row.clip, s].tolist(), pose.tolist()) for s in adm}
        d2 = {s: v for s, v in d2.items() if v != 0.0}
        if not d2:
            assert row.start == -1 and np.isnan(row.pose_dist) and row.position == -1
            continue
        best = min(d2, key=lambda s: (d2[s], s))
        assert row.start == best and row.pose_dist == np.sqrt(d2[best])
        assert row.audio_dist == cosine_distance(db.F[row.clip, best].tolist(), q[2].tolist())
    r = e.ranking()
    assert list(r["position"]) == list(range(len(r)))
    assert (r["combined"].diff().dropna() >= 0).all()
    assert (r["combined"] == r["pose_rank"] + r["audio_rank"]).all()
    assert sorted(r["pose_rank"]) == sorted(r["audio_rank"]) == list(range(len(r)))
    assert r.iloc[1]["chosen"] and e.table["chosen"].sum() == 1  # k = 1: the second place
    # the window at distance 0 (the query's own frame) is never a candidate
    assert not ((e.table["clip"] == 2) & (e.table["start"] == 5)).any()


def test_k_beyond_the_survivors_takes_the_last_and_relaxing_drops_the_control():
    db = _db(5, M=4)
    q = np.ones((4, 5), np.float32)
    e = explain_step(db, q, db.P[0, 0], k=50, segment=2)
    assert e.position == e.n_survivors - 1
    none = np.zeros(db.valid.shape, bool)
    r = explain_step(db, q, db.P[0, 0], segment=2, mask=none)
    free = explain_step(db, q, db.P[0, 0], segment=2)
    assert r.relaxed and not free.relaxed and (r.clip, r.start) == (free.clip, free.start)


def test_bad_inputs_raise_config_errors():
    db = _db(1)
    q = np.zeros((5, 5), np.float32)
    with pytest.raises(ConfigError, match="query_features"):
        explain_step(db, q[:, :3], db.P[0, 0])
    with pytest.raises(ConfigError, match="pose"):
        explain_step(db, q, db.P[0, 0, :3])
    with pytest.raises(ConfigError, match="t must be"):
        explain_step(db, q, db.P[0, 0], t=5)
    with pytest.raises(ConfigError, match="mask must have shape"):
        explain_step(db, q, db.P[0, 0], mask=np.ones((2, 2), bool))
    with pytest.raises(ConfigError, match="mask_rule"):
        explain_step(db, q, db.P[0, 0], mask_rule="some")
    with pytest.raises(ConfigError, match="no database window"):
        explain_step(db, q, db.P[0, 0], exclude=np.ones(db.valid.shape, bool))


@pytest.fixture(scope="module")
def small_db():
    takes = [make_take(20.0, seed=s, name=f"t{s}") for s in range(3)]
    return MatchingDatabase.build(takes, config=BuildConfig())


def test_synthesis_steps_are_explained_with_their_controls_and_exclusions(small_db):
    db = small_db
    audio = make_take(6.0, seed=9).audio
    cfg = SynthesisConfig(k=1, seed=3, control="0-2:left_hand=high,3-5:speed=slow", exclude_takes=("t1",))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", GestureKitWarning)
        res = synthesize(audio, db=db, config=cfg)
    for i in range(res.search.n_steps):
        inp = step_inputs(res, db, i)
        assert inp["t"] == i * cfg.segment and inp["k"] == 1
        assert (inp["mask"] is not None) == (i in (0, 1, 2, 3, 6, 7, 8))  # middle frame 8i+3 controlled
        e = _check_step(
            db,
            res.search,
            inp["query_features"],
            i,
            N=cfg.segment,
            k=1,
            mask=inp["mask"],
            exclude=inp["exclude"],
            rule=cfg.mask_rule,
        )
        assert int(db.clip_take[e.clip]) != 1  # the excluded take is never used
        same = explain_synthesis_step(res, db, i)
        assert (same.clip, same.start) == (e.clip, e.start)
    with pytest.raises(ConfigError, match="step must be in"):
        step_inputs(res, db, res.search.n_steps)


# ---- figures ----------------------------------------------------------------------------------------


def test_rankings_figure_places_every_survivor_by_its_two_ranks():
    db = _db(8, M=12)
    q = np.random.default_rng(2).normal(size=(3, 5)).astype(np.float32)
    e = explain_step(db, q, db.P[1, 1], segment=3, k=2)
    fig = rankings_figure(e, names={int(e.clip): "take a, 1.0 s"})
    parts = {t.meta["part"]: t for t in fig.data}
    r = e.ranking()
    np.testing.assert_array_equal(parts["clips"].x, r["pose_rank"])
    np.testing.assert_array_equal(parts["clips"].y, r["audio_rank"])
    chosen = r[r["chosen"]].iloc[0]
    assert (parts["chosen"].x[0], parts["chosen"].y[0]) == (chosen["pose_rank"], chosen["audio_rank"])
    line = [s for s in fig.layout.shapes if s.name == "combined rank"][0]
    assert line.y0 == line.x1 == chosen["combined"]  # x + y = combined through the chosen clip
    assert any("take a, 1.0 s" in h for h in parts["clips"].hovertext)


def test_feature_blocks_tile_the_layout_and_the_heatmap_marks_them():
    a, p = feature_blocks("audio"), feature_blocks("pose")
    assert len(a) == len(LAYOUT.audio_offsets) and len(p) == len(LAYOUT.pose_offsets)
    for blocks, total in ((a, LAYOUT.audio_dim), (p, LAYOUT.pose_dim)):
        cols = np.concatenate([np.arange(total)[s] for s in blocks.values()])
        np.testing.assert_array_equal(cols, np.arange(total))
    assert list(a)[1] == "m(t+2)"
    with pytest.raises(ConfigError):
        feature_blocks("motion")
    v = np.random.default_rng(0).normal(size=(30, LAYOUT.audio_dim))
    fig = feature_figure(v, blocks=a, fps=15.0)
    hm = fig.data[0]
    assert hm.meta["part"] == "features" and np.shape(hm.z) == (LAYOUT.audio_dim, 30)
    assert np.isclose(hm.x[-1], 29 / 15.0)
    assert sorted(s.name for s in fig.layout.shapes) == sorted(a)
    assert list(fig.layout.yaxis.ticktext) == list(a) and fig.layout.yaxis.tickvals[1] == 14 + 6.5
    with pytest.raises(ConfigError):
        feature_figure(np.zeros(5))


# ---- tables -----------------------------------------------------------------------------------------


def test_constraints_table_counts_what_each_constraint_admits(small_db):
    db = small_db
    table = constraints_table(db, segment=8).set_index("constraint")
    assert len(table) == sum(len(v) for _, v in CONSTRAINTS.values())
    attrs = np.asarray(db.attributes)
    lo, hi = db.thresholds["left_hand_height"]
    height = attrs[..., ATTRIBUTE_NAMES.index("left_hand_height")]
    row = table.loc["left_hand=low"]
    assert row["side"] == "below" and row["threshold"] == f"{lo:.3f}"
    assert row["frames"] == pytest.approx(np.mean(height < lo))
    high = height > hi
    ends = sum(
        window_admissible(m, s, 8, valid=db.valid, mask=high, rule="ends") for m in range(db.n_clips) for s in range(64)
    )
    every = sum(
        window_admissible(m, s, 8, valid=db.valid, mask=high, rule="all") for m in range(db.n_clips) for s in range(64)
    )
    assert (table.loc["left_hand=high", "windows_ends"], table.loc["left_hand=high", "windows_all"]) == (ends, every)
    assert (table["windows_all"] <= table["windows_ends"]).all()
    assert table.loc["both_hands=high", "attributes"] == "left_hand_height+right_hand_height"


def test_synthesis_and_motion_tables_measure_the_outputs(small_db):
    db = small_db
    audio = make_take(4.0, seed=11).audio
    results = [synthesize(audio, db=db, config=SynthesisConfig(k=k, segment=n, seed=1)) for k, n in ((0, 8), (3, 4))]
    table = synthesis_table(results)
    assert list(table["label"]) == ["k=0, N=8", "k=3, N=4"]
    for row, r in zip(table.itertuples(), results):
        s = r.search
        assert row.steps == s.n_steps and row.clips_used == len(set(s.clip.tolist()))
        assert row.pose_dist == pytest.approx(np.mean(s.cand_pose_dist[np.arange(s.n_steps), s.position]))
        assert row.audio_dist == pytest.approx(np.mean(s.cand_audio_dist[np.arange(s.n_steps), s.position]))
        joins = metrics.boundary_jumps(r.motion.positions, np.arange(1, s.n_steps) * row.segment)
        assert row.boundary_jump == pytest.approx(joins["jump"])
    with pytest.raises(ConfigError, match="labels"):
        synthesis_table(results, labels=["one"])

    m = results[0].motion
    still = Motion(np.repeat(m.positions[:1], m.n_frames, axis=0), m.fps)
    measures = motion_measures([m, still], labels=["knn", "still"], boundaries=[8, 16], audio=audio)
    assert list(measures["label"]) == ["knn", "still"]
    assert measures.loc[1, "mean_jerk"] == 0 and measures.loc[1, "beat_consistency"] == 0  # no motion, no beats
    assert measures.loc[0, "mean_jerk"] == pytest.approx(metrics.mean_jerk(m.positions, fps=15))
    assert "beat_consistency" not in motion_measures([m]).columns


def test_control_statistics_measure_each_segment_and_the_free_run_whole(small_db):
    db = small_db
    m = synthesize(make_take(6.0, seed=12).audio, db=db, config=SynthesisConfig(seed=2)).motion
    track = "0-2:left_hand=high,3-5:speed=slow"
    table = control_statistics([("a", m, track), ("b", m, "")], thresholds=db.thresholds)
    direct = metrics.control_adherence(m.positions, parse_control(track), thresholds=db.thresholds, fps=15)
    a = table[table["label"] == "a"].drop(columns="label").reset_index(drop=True)
    pd.testing.assert_frame_equal(a, direct)
    free = table[table["label"] == "b"].iloc[0]
    height = frame_attributes(m.positions, fps=15)[:, ATTRIBUTE_NAMES.index("left_hand_height")]
    assert free["constraint"] == "none" and np.isnan(free["adherence"]) and free["frames"] == m.n_frames
    assert free["left_hand_height_mean"] == pytest.approx(height.mean())
    assert free["left_hand_height_std"] == pytest.approx(height.std())
    with pytest.raises(ConfigError, match="thresholds lack"):
        control_statistics([("a", m, track)], thresholds={"left_hand_height": (0, 1)})
