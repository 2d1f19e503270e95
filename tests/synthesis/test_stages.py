"""The synthesis's stages (features, plan, search, assemble, refine) run one by one equal the whole.

The Synthesizer owns its search index (nothing is kept in the database object), computes the
refiner's audio features once with the query, and searches plans as the plain search does with
each plan's arrays.
"""

from __future__ import annotations

import gc
import warnings
import weakref

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import gesturekit
from gesturekit.database import MatchingDatabase
from gesturekit.demo import build_demo_database
from gesturekit.errors import ConfigError, GestureKitWarning
from gesturekit.features import audio_frame_features, cgan_audio_features, stack_audio_features
from gesturekit.search import SearchConfig, SearchRequest, plan_search
from gesturekit.search.plan import stack_plans
from gesturekit.synthesis import (
    SynthesisConfig,
    Synthesizer,
    search_request,
    synthesize,
    synthesize_batch,
    synthesizer_for,
)

CONTROLLED = SynthesisConfig(k=2, seed=3, init="rest", blend="offset", control="0-2:left_hand=high,3-5:speed=slow")


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    path = tmp_path_factory.mktemp("demo") / "db"
    build_demo_database(path, minutes=4.0)
    return MatchingDatabase.load(path)


@pytest.fixture(scope="module")
def speech():
    from gesturekit.datasets.synthetic import generate_demo_take

    take, _ = generate_demo_take(seconds=8.0, seed=11, name="query")
    return take.audio


def _same_result(a, b) -> None:
    assert a.search.equals(b.search) and a.config == b.config
    np.testing.assert_array_equal(a.motion.positions, b.motion.positions)
    np.testing.assert_array_equal(a.knn_motion.positions, b.knn_motion.positions)
    assert (a.database, a.source, a.one_skeleton, a.refiner) == (b.database, b.source, b.one_skeleton, b.refiner)
    for name in ("query", "masks", "step_mask_index", "exclude"):
        np.testing.assert_array_equal(getattr(a.plan, name), getattr(b.plan, name))


@pytest.mark.slow
@pytest.mark.parametrize("config", [SynthesisConfig(), CONTROLLED], ids=["default", "controlled"])
def test_the_stages_one_by_one_give_what_synthesize_gives(db, speech, config):
    syn = Synthesizer(db)
    feats = syn.features(speech)
    plan = syn.plan(feats, config)
    (found,) = syn.search([plan])
    staged = syn.assemble(feats, plan, found, config)
    _same_result(staged, synthesize(speech, db=db, config=config))
    assert staged.n_frames == feats.n_frames == len(speech) * 15 // 16000 and staged.audio is feats.samples


def test_the_query_holds_the_refiners_features_as_the_refiner_would_compute_them(db, speech):
    feats = Synthesizer(db).features(speech)
    # the plain definitions: frame features, stacked and z-scored for the search, m and dm/dt for the cGAN
    m = audio_frame_features(speech, n_frames=feats.n_frames)
    np.testing.assert_array_equal(feats.audio, cgan_audio_features(m))
    np.testing.assert_array_equal(feats.query, db.zscore("F").apply(stack_audio_features(m)).astype(np.float32))
    # and what the database's query features give (the refiner's input before the stages kept it)
    query, audio = db.query_features(speech, n_frames=feats.n_frames)
    np.testing.assert_array_equal(feats.audio, audio)
    np.testing.assert_array_equal(feats.query, query)
    assert feats.query.dtype == feats.audio.dtype == np.float32 and feats.audio.shape == (feats.n_frames, 28)


def test_the_refine_stage_gives_what_synthesize_with_the_refiner_gives(db, speech):
    pytest.importorskip("torch")
    from gesturekit.refine import open_refiner

    refiner = open_refiner("demo")
    syn = Synthesizer(db, refiner=refiner)
    feats = syn.features(speech)
    plan = syn.plan(feats, CONTROLLED)
    result = syn.assemble(feats, plan, syn.search([plan])[0], CONTROLLED)
    knn = result.knn_motion.positions.copy()
    assert syn.refine(result, feats) is result and result.motion is result.refined_motion
    whole = synthesize(speech, db=db, config=CONTROLLED, refiner=refiner)
    _same_result(result, whole)
    np.testing.assert_array_equal(result.refined_motion.positions, whole.refined_motion.positions)
    np.testing.assert_array_equal(result.knn_motion.positions, knn)  # the k-NN motion is kept as it was
    assert not np.array_equal(result.motion.positions, knn)


def test_refining_needs_a_refiner_and_the_results_own_features(db, speech):
    syn = Synthesizer(db)
    feats = syn.features(speech)
    plan = syn.plan(feats, SynthesisConfig())
    result = syn.assemble(feats, plan, syn.search([plan])[0], SynthesisConfig())
    with pytest.raises(ConfigError, match="no refiner"):
        syn.refine(result, feats)
    with pytest.raises(ConfigError, match="do not fit a result"):
        syn.refine(result, syn.features(speech[:16000]))


def test_two_synthesizers_over_one_database_share_nothing_hidden_in_it(db, speech):
    before = dict(vars(db))
    a, b = Synthesizer(db), Synthesizer(db)
    assert a.index is a.index and a.index is not b.index  # each owns its index
    assert a.with_refiner(None).index is a.index  # shared only when asked for
    assert synthesizer_for(db).index is synthesizer_for(db).index  # the functions' explicit cache
    assert synthesizer_for(db).index is not a.index
    synthesize(speech[:32000], db=db)
    assert vars(db).keys() == before.keys() and all(vars(db)[k] is v for k, v in before.items())
    _same_result(a.run([speech], [CONTROLLED])[0], b.run([speech], [CONTROLLED])[0])


def test_the_shared_index_keeps_no_database_alive(tmp_path):
    build_demo_database(tmp_path / "db", minutes=1.0)
    db = MatchingDatabase.load(tmp_path / "db")
    ref = weakref.ref(db)
    synthesize(np.zeros(16000, np.float32), db=db)
    syn = synthesizer_for(db)
    assert syn.db is db
    del db, syn
    gc.collect()
    assert ref() is None


def test_the_synthesizer_is_exported_by_the_package():
    assert gesturekit.Synthesizer is Synthesizer and "Synthesizer" in gesturekit.__all__


@settings(max_examples=10, deadline=None)
@given(
    segment=st.sampled_from([4, 6, 8]),
    controls=st.lists(
        st.sampled_from(["", "0-2:left_hand=high", "1-3:speed=slow", "0-1:left_hand=low,2-4:speed=fast"]),
        min_size=1,
        max_size=3,
    ),
    seeds=st.integers(0, 5),
    exclude=st.booleans(),
)
def test_searching_plans_equals_searching_each_plans_arrays(db, speech, segment, controls, seeds, exclude):
    """The batched search of plans (their masks stacked, indices moved along) equals the plain search
    of each plan's own arrays, one at a time."""
    syn = synthesizer_for(db)
    takes = (db.take_names[0],) if exclude else ()
    configs = [
        SynthesisConfig(segment=segment, seed=seeds + i, control=c, exclude_takes=takes) for i, c in enumerate(controls)
    ]
    plans = [syn.plan(syn.features(speech[: 16000 * (3 + i)]), c) for i, c in enumerate(configs)]
    with warnings.catch_warnings():  # a control may be relaxed; both searches say so alike
        warnings.simplefilter("ignore", GestureKitWarning)
        batch = syn.index.search_plans(plans, fps=db.fps)
        for plan, got in zip(plans, batch):
            alone = syn.index.search(
                plan.query,
                config=plan.config,
                masks=plan.masks,
                step_mask_index=plan.step_mask_index,
                exclude=plan.exclude,
            )
            assert got.equals(alone)


def test_a_batch_of_plans_shares_its_exclusions(db, speech):
    syn = synthesizer_for(db)
    feats = syn.features(speech)
    plans = [syn.plan(feats, SynthesisConfig()), syn.plan(feats, SynthesisConfig(exclude_takes=(db.take_names[0],)))]
    with pytest.raises(ConfigError, match="exclude the same database frames"):
        stack_plans(plans)
    with pytest.raises(ConfigError, match="exclude the same database takes"):
        synthesize_batch([speech, speech], db=db, config=[SynthesisConfig(), SynthesisConfig(exclude_takes=("x",))])


def test_planning_takes_search_values_not_a_synthesis_config(db, speech):
    config = SynthesisConfig(segment=6, init="rest", control="1-3:speed=slow", exclude_takes=(db.take_names[0],))
    request = search_request(config)
    assert request == SearchRequest(
        search=config.search,
        init="rest",
        control=config.control_track,
        exclude_takes=config.exclude_takes,
        exclude_ranges=(),
    )
    query = Synthesizer(db).features(speech).query
    plan = plan_search(db, query, request)
    assert plan.segment == 6 and plan.config.init_pose != "random" and plan.exclude is not None
    with pytest.raises(ConfigError, match="request must be a SearchRequest"):
        plan_search(db, query, config)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"query must be the speech's features.*Synthesizer\.features"):
        plan_search(db, speech, request)  # samples, not features
    with pytest.raises(ConfigError, match="init must be"):
        SearchRequest(search=SearchConfig(), init="seated")


def test_the_modules_that_drive_the_search_import_no_private_names():
    """Synthesis, live, the search and the baselines use each other's public names only."""
    import ast
    from pathlib import Path

    root = Path(gesturekit.__file__).resolve().parent
    files = sorted((root / "synthesis").glob("*.py")) + [root / "live.py"]
    files += sorted((root / "search").glob("*.py")) + [root / "evaluate" / "baselines.py"]
    private = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.level or (node.module or "").startswith("gesturekit")):
                names = [a.name for a in node.names if a.name.startswith("_") and not a.name.endswith("__")]
                private += [f"{path.name}: {name}" for name in names]
    assert private == []


def test_a_synthesis_with_its_scan_on_a_torch_device_gives_the_same_motion(db, speech, monkeypatch):
    # torch's CPU device stands in for a GPU: the path and the index are the device's own
    pytest.importorskip("torch")
    here = synthesize(speech, db=db, config=CONTROLLED)
    there = synthesize(speech, db=db, config=CONTROLLED, search_device="cpu:0")
    _same_result(here, there)
    assert synthesizer_for(db, search_device="cpu:0").index._device is not None
    assert synthesizer_for(db).index._device is None  # each device its own index
    assert synthesizer_for(db, search_device="cpu").index is synthesizer_for(db).index  # "cpu": the CPU's own
    monkeypatch.setenv("GESTUREKIT_SEARCH_DEVICE", "cpu:0")  # the default of a synthesis naming none
    assert synthesizer_for(db).index is synthesizer_for(db, search_device="cpu:0").index
    assert Synthesizer(db).index._device is not None
    _same_result(synthesize(speech, db=db, config=CONTROLLED), here)
    monkeypatch.setenv("GESTUREKIT_SEARCH_DEVICE", "abacus")
    with pytest.raises(ConfigError, match="'abacus' is not a torch device"):
        synthesize(speech[:16000], db=db)
    with pytest.raises(ConfigError, match="torch device name"):
        synthesizer_for(db, search_device=3)
