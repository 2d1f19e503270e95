"""SearchResult.chosen_distances: the chosen windows' mean distances, against a plain loop."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.search import SearchConfig, SearchResult


@st.composite
def results(draw):
    n_steps, width = draw(st.integers(1, 12)), draw(st.integers(1, 6))
    r = SearchResult.empty(n_steps, n_steps * 8, width, config=SearchConfig(), init_pose=[0.0], init_frame=(0, 0))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    r.cand_pose_dist[:] = rng.uniform(0, 5, (n_steps, width))
    r.cand_audio_dist[:] = rng.uniform(0, 2, (n_steps, width))
    r.position[:] = rng.integers(-1, width, n_steps)  # -1: a pin outside the record
    return r


def plain(r: SearchResult) -> tuple[float, float]:
    pose, audio = [], []
    for step in range(r.n_steps):
        p = int(r.position[step])
        if p >= 0:
            pose.append(float(r.cand_pose_dist[step, p]))
            audio.append(float(r.cand_audio_dist[step, p]))
    if not pose:
        return math.nan, math.nan
    return sum(pose) / len(pose), sum(audio) / len(audio)


@settings(max_examples=80, deadline=None)
@given(results())
def test_chosen_distances_are_the_plain_means_over_steps_with_a_choice_in_the_record(r):
    got, want = r.chosen_distances(), plain(r)
    for g, w in zip(got, want):
        assert (math.isnan(g) and math.isnan(w)) or g == pytest.approx(w, rel=1e-12, abs=1e-12)
