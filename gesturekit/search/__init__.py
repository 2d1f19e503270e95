"""Algorithm 1 of the paper (the k-NN motion search), fast and exact.

:func:`search` runs the search on plain arrays and returns a :class:`SearchResult`
(the chosen (clip, start) per step, the output frames, a record of every step's
best candidates); :func:`search_batch` serves several queries with one scan of the
database per step; :class:`SearchIndex` keeps a database prepared between searches.
The fast search equals :func:`gesturekit.search.reference.search_reference`, the
algorithm written out loop for loop, decision for decision.

Modules
-------
types
    :class:`SearchConfig`, :class:`SearchResult`, :func:`describe_steps`.
plan
    :func:`plan_search`: a search's inputs, built once (:class:`SearchPlan`) from what it is
    asked for (:class:`SearchRequest`); :meth:`SearchIndex.search_plans` searches plans.
reference
    Algorithm 1 loop for loop: the definition the fast search reproduces.
explain
    One step taken apart for every clip of the database (:func:`~gesturekit.search.explain.explain_step`).
admissible
    Which windows a step may use, vectorised (:func:`admissible_starts`), used by all of them.
exact
    The exact distances, vectorised, and the error bounds of the float32 estimates.
checks
    Input checks shared by the fast search and the reference.
index
    :class:`SearchIndex`: the fast exact search.
stream
    :class:`~gesturekit.search.stream.StepSearch`: the same search one step at a time, for a
    query that grows (live synthesis).
threads
    Thread and BLAS control while a search runs.
kernels
    The compiled (numba) loops, imported when a search first runs.
"""

from __future__ import annotations

from .admissible import admissible_starts
from .exact import exact_cosine_distance, exact_pose_sqdist
from .index import SearchIndex, search, search_batch
from .plan import SearchPlan, SearchRequest, plan_search
from .types import SearchConfig, SearchResult, describe_steps

__all__ = [
    "SearchConfig",
    "SearchResult",
    "SearchIndex",
    "SearchPlan",
    "SearchRequest",
    "plan_search",
    "search",
    "search_batch",
    "exact_pose_sqdist",
    "exact_cosine_distance",
    "admissible_starts",
    "describe_steps",
]
