"""What a search step must know of a clip it does not read (docs/METHOD.md, "Exact arithmetic").

The rule stated there: a clip whose lower bounds place it after every deciding clip of those
read (combined rank, counted over the clips read, at most the table's last) in both rankings
changes neither the listed clips, nor their ranks, nor the choice, so it may be left unread;
being after the listed clips only is not enough. These tests hold the rule against
:func:`gesturekit.search.reference.search_reference` on the adversarial databases of
``test_search.py`` (exact ties, duplicated clips, zero audio vectors, controls, exclusions, k > 0).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given

from gesturekit.errors import ConfigError
from gesturekit.search import SearchConfig
from gesturekit.search.reference import cosine_distance, pose_sqdist, search_reference, window_admissible

from .test_search import SLOW, problems


def survivors(P, F, valid, p_prev, f_t, n, exclude, mask, rule):
    """Per clip in clip order, ``(clip, start, d2, audio)`` at its nearest admissible non-zero start,
    and per clip the least pose and audio distances over all its admissible starts (what a bound
    over the clip can at best give)."""
    M, T = valid.shape
    rows, least = [], {}
    for m in range(M):
        best = (-1, np.inf)
        lo_d, lo_a = np.inf, np.inf
        for s in range(T):
            if not window_admissible(m, s, n, valid=valid, exclude=exclude, mask=mask, rule=rule):
                continue
            d2 = pose_sqdist(P[m, s].tolist(), p_prev)
            a = cosine_distance(F[m, s].tolist(), f_t)
            lo_d, lo_a = min(lo_d, d2), min(lo_a, a)
            if d2 != 0.0 and d2 < best[1]:
                best = (s, d2)
        if best[0] >= 0:
            rows.append((m, best[0], best[1], cosine_distance(F[m, best[0]].tolist(), f_t)))
            least[m] = (lo_d, lo_a)
    return rows, least


def table(rows, width):
    """Rule 4 over ``rows``: the first ``width`` of the combined ranking as (clip, start, pose rank,
    audio rank, combined), ranks counted over ``rows`` only, ties by clip index."""
    by_pose = sorted(rows, key=lambda r: (r[2], r[0]))
    by_audio = sorted(rows, key=lambda r: (r[3], r[0]))
    pose_rank = {r[0]: i for i, r in enumerate(by_pose)}
    audio_rank = {r[0]: i for i, r in enumerate(by_audio)}
    order = sorted(rows, key=lambda r: (pose_rank[r[0]] + audio_rank[r[0]], r[0]))
    return [(r[0], r[1], pose_rank[r[0]], audio_rank[r[0]], pose_rank[r[0]] + audio_rank[r[0]]) for r in order[:width]]


def steps(P, F, valid, query, kw):
    """Per step of the reference search: its survivors, clip bounds, table width and result row."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            res = search_reference(P, F, valid, query, **kw)
        except ConfigError:  # no admissible window at some step: nothing to rank
            return
    cfg = res.config
    N, width = cfg.segment, cfg.table_width
    masks, index = kw.get("masks"), kw.get("step_mask_index")
    p_prev = res.init_pose.tolist()
    for i in range(res.clip.size):
        j = -1 if index is None or res.relaxed[i] else int(index[i])
        mask = None if j < 0 else masks[j]
        rows, least = survivors(P, F, valid, p_prev, query[i * N].tolist(), N, kw.get("exclude"), mask, cfg.mask_rule)
        yield rows, least, width, res, i
        p_prev = P[res.clip[i], res.start[i] + N - 1].tolist()


def deciding(rows, width):
    """The clips of ``rows`` whose combined rank, counted over ``rows`` only, is at most the
    ``width``-th smallest: the only clips whose ranks the table can show."""
    if not rows:
        return []
    by_pose = sorted(rows, key=lambda r: (r[2], r[0]))
    by_audio = sorted(rows, key=lambda r: (r[3], r[0]))
    combined = {r[0]: 0 for r in rows}
    for order in (by_pose, by_audio):
        for i, r in enumerate(order):
            combined[r[0]] += i
    last = sorted(combined.values())[min(width, len(rows)) - 1]
    return [r for r in rows if combined[r[0]] <= last]


def may_leave_unread(kept, bounds, width):
    """The rule of METHOD.md: clips known only by lower bounds ``(pose, audio)`` may be left
    unread when each lies above every deciding clip of the read ones in both rankings."""
    top = deciding(kept, width)
    if not top:
        return not bounds
    d_top, a_top = max(r[2] for r in top), max(r[3] for r in top)
    return all(d > d_top and a > a_top for d, a in bounds)


@pytest.mark.slow
@SLOW
@given(problems(max_clips=40))
def test_clips_after_the_deciding_ones_in_both_rankings_change_nothing(prob):
    P, F, valid, query, kw = prob
    for rows, least, width, res, i in steps(P, F, valid, query, kw):
        full = table(rows, width)
        # the literal table is the reference's (anchors `table` to the definition)
        n = len(full)
        assert [r[0] for r in full] == res.cand_clip[i, :n].tolist()
        assert [r[1] for r in full] == res.cand_start[i, :n].tolist()
        assert [r[2] for r in full] == res.cand_pose_rank[i, :n].tolist()
        assert [r[3] for r in full] == res.cand_audio_rank[i, :n].tolist()
        assert [r[4] for r in full] == res.cand_combined[i, :n].tolist()
        top = deciding(rows, width)
        if not top:
            continue
        d_top, a_top = max(r[2] for r in top), max(r[3] for r in top)
        # candidates: beyond the deciding clips at the nearest start, or by the best clip bound;
        # the rule is then checked on what is read, as a search would, shrinking until it holds
        beyond = [r for r in rows if r[2] > d_top and r[3] > a_top]
        for skipped in (beyond, [r for r in beyond if least[r[0]][0] > d_top and least[r[0]][1] > a_top], beyond[::2]):
            skipped = list(skipped)
            while skipped:
                kept = [r for r in rows if r not in skipped]
                if may_leave_unread(kept, [least[r[0]] for r in skipped], width) or may_leave_unread(
                    kept, [(r[2], r[3]) for r in skipped], width
                ):
                    break
                skipped.pop()
            kept = [r for r in rows if r not in skipped]
            # the choice is a row of the table; `short` needs only the count of survivors,
            # which admissibility gives without reading a clip's features
            assert table(kept, width) == full


def test_leaving_out_clips_after_the_listed_ones_only_can_change_the_table():
    """Being after the listed clips is not enough: a clip left out may stand before an unlisted
    clip in one ranking, whose rank then drops and overtakes a listed one. Hence the rule
    compares with every clip whose combined rank, counted over the read clips, could list it."""
    rows = [(0, 0, 3.0, 0.5), (1, 0, 1.0, 0.6), (2, 0, 2.0, 0.7)]  # (clip, start, d2, audio)
    full = table(rows, 1)
    assert full == [(1, 0, 0, 1, 1)]
    kept = rows[:2]  # clip 2 is after listed clip 1 in both rankings, before clip 0 in pose
    assert table(kept, 1) == [(0, 0, 1, 0, 1)] != full
    assert not may_leave_unread(kept, [(2.0, 0.7)], 1)


def test_a_clip_after_the_listed_in_pose_only_changes_their_audio_ranks():
    """The farthest clip in pose with the nearest audio: leaving it unread changes every listed
    clip's audio rank, so bounds in pose space alone cannot leave a clip unread."""
    M, T, D, A = 4, 16, 3, 2
    P = np.zeros((M, T, D), np.float32)
    F = np.zeros((M, T, A), np.float32)
    for m in range(M):
        P[m, :, 0] = 1.0 + m  # clip m at pose distance about (1 + m) from the origin
        F[m, :, 0] = 1.0
        F[m, :, 1] = 3.0 - m  # clip 3 has the audio nearest the query (1, 0)
    valid = np.ones((M, T), bool)
    query = np.tile(np.array([1.0, 0.0], np.float32), (8, 1))
    kw = {"config": SearchConfig(record=2, init_pose=(0.0,) * D)}
    rows, least, width, res, i = next(steps(P, F, valid, query, kw))
    full = table(rows, width)
    listed = {r[0] for r in full}
    assert 3 not in listed
    d_top = max(r[2] for r in rows if r[0] in listed)
    assert all(r[2] > d_top for r in rows if r[0] == 3)  # after every listed clip in pose
    kept = [r for r in rows if r[0] != 3]
    assert table(kept, width) != full
    assert [r[3] for r in table(kept, width)] != [r[3] for r in full]
