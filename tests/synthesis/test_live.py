"""Streaming synthesis (gesturekit.live): the motion streamed equals the offline synthesis."""

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gesturekit.control import parse_control
from gesturekit.database import MatchingDatabase
from gesturekit.demo import build_demo_database
from gesturekit.errors import ConfigError, GestureKitWarning
from gesturekit.export.npz import load_npz
from gesturekit.export.result import save_result_npz
from gesturekit.features import LAYOUT, frame_centres
from gesturekit.live import LiveSynthesizer
from gesturekit.synthesis import SynthesisConfig, SynthesisResult, synthesize
from tests.waits import wait_until

SR = 16000


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    path = tmp_path_factory.mktemp("live") / "db"
    build_demo_database(path, minutes=2.0)
    return MatchingDatabase.load(path)


@pytest.fixture(scope="module")
def speech():
    from gesturekit.datasets.synthetic import generate_demo_take

    take, _ = generate_demo_take(seconds=5.0, seed=7, name="query")
    return take.audio


def stream(db, audio, chunks, *, config=None, switches=(), refiner=None):
    """Push ``audio`` in pieces of the given sizes (cycled); ``switches`` are (sample, control)
    set just before the first push reaching that sample. Returns (live, returned pieces, frames
    returned before each switch)."""
    live = LiveSynthesizer(db, config=config, refiner=refiner)
    pending = sorted(switches)
    pieces, before = [], []
    pos, k = 0, 0
    while pos < len(audio):
        while pending and pending[0][0] <= pos:
            before.append(live.frames_out)
            live.set_control(pending.pop(0)[1])
        size = chunks[k % len(chunks)]
        k += 1
        pieces.append(live.push(audio[pos : pos + size]))
        pos += size
    pieces.append(live.finish())
    return live, pieces, before


def check_equal_to_offline(db, audio, live: LiveSynthesizer, pieces, config=None):
    res = live.result()
    motion = np.concatenate(pieces)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        offline = synthesize(audio, db=db, config=res.config)
    assert res.config.to_dict() == offline.config.to_dict()
    if config is not None:  # apart from the control track, the options given
        assert res.config.with_control("") == config.with_control("")
    assert motion.dtype == np.float32 and motion.shape == offline.motion.positions.shape
    np.testing.assert_array_equal(motion, offline.motion.positions)
    np.testing.assert_array_equal(res.motion.positions, offline.motion.positions)
    np.testing.assert_array_equal(res.knn_motion.positions, offline.knn_motion.positions)
    assert res.search.equals(offline.search)
    np.testing.assert_array_equal(res.audio, audio)
    assert res.plan is not None and offline.plan is not None
    np.testing.assert_array_equal(res.plan.query, offline.plan.query)
    np.testing.assert_array_equal(res.plan.step_mask_index, offline.plan.step_mask_index)
    assert (res.plan.masks is None) == (offline.plan.masks is None)
    if res.plan.masks is not None:
        np.testing.assert_array_equal(res.plan.masks, offline.plan.masks)
    assert res.plan.config == offline.plan.config
    assert res.motion.joints == db.joint_presence
    return res, offline


@pytest.mark.slow
@pytest.mark.parametrize("chunk", [1, 160, 320, 16000])
@pytest.mark.parametrize("switched", [False, True], ids=["free", "switched"])
def test_streamed_motion_equals_synthesize(db, speech, chunk, switched):
    audio = speech[: int(2.5 * SR)] if chunk == 1 else speech  # 40,000 single-sample pushes stay fast
    switches = [(int(1.4 * SR), "left_hand=high"), (int(2.3 * SR), None)] if switched else []
    live, pieces, before = stream(db, audio, [chunk], switches=switches)
    res, _ = check_equal_to_offline(db, audio, live, pieces)
    assert sum(len(p) for p in pieces[:-1]) > 0  # frames came out before the end
    assert live.frames_out == res.n_frames == len(audio) * 15 // SR
    if switched:
        segments = res.control.segments
        assert len(segments) == 1 and segments[0].label() == "left_hand=high"
        # the control holds from the first step not yet taken when it was switched
        assert round(segments[0].start_s * 15) == before[0] and round(segments[0].end_s * 15) == before[1]


def test_offline_control_track_and_options_stream_equally(db, speech):
    config = SynthesisConfig(
        control="0.5-2:left_hand=low,2.4-4:speed=slow+left_hand=high",
        segment=6,
        k=1,
        seed=3,
        init="rest",
        blend="offset",
        blend_frames=9,  # longer than a step: a join's fade runs into the next step
        exclude_ranges=((db.take_names[0], 0.0, 30.0),),
    )
    live, pieces, _ = stream(db, speech, [555], config=config)
    res, _ = check_equal_to_offline(db, speech, live, pieces, config)
    assert res.config.control == config.control


@pytest.mark.parametrize(
    "options",
    [{"segment": 1}, {"segment": 2, "blend": "offset"}, {"segment": 20}, {"segment": 8, "mask_rule": "all"}],
    ids=["N1", "N2-offset", "N20", "mask-all"],
)
def test_step_lengths_and_switches_stream_equally(db, speech, options):
    config = SynthesisConfig(**options)
    switches = [(int(1.1 * SR), "left_hand=high"), (int(1.9 * SR), "left_hand=low+speed=slow"), (int(3 * SR), "")]
    live, pieces, _ = stream(db, speech, [1000], config=config, switches=switches)
    check_equal_to_offline(db, speech, live, pieces, config)


@pytest.mark.slow
@settings(
    max_examples=8, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow]
)
@given(
    chunks=st.lists(st.integers(1, 9000), min_size=1, max_size=6),
    at=st.floats(0.0, 2.5),
    control=st.sampled_from(["left_hand=high", "right_hand=low", "speed=fast", None]),
)
def test_any_chunking_gives_the_same_motion(db, speech, chunks, at, control):
    audio = speech[: int(3.2 * SR)]
    live, pieces, _ = stream(db, audio, chunks, switches=[(int(at * SR), control)])
    check_equal_to_offline(db, audio, live, pieces)


def test_a_control_switched_at_t_changes_no_frame_before_t(db, speech):
    plain, plain_pieces, _ = stream(db, speech, [320])
    free = np.concatenate(plain_pieces)
    live = LiveSynthesizer(db)
    returned = [live.push(speech[: int(2.5 * SR)])]
    t = live.frames_out
    live.set_control("left_hand=low")
    returned.append(live.push(speech[int(2.5 * SR) :]))
    returned.append(live.finish())
    motion = np.concatenate(returned)
    np.testing.assert_array_equal(returned[0], free[:t])  # what was returned never changes
    np.testing.assert_array_equal(motion[:t], free[:t])
    assert not np.array_equal(motion[t:], free[t:])  # the control does act after t
    seg = live.result().control.segments[0]
    assert round(seg.start_s * 15) == t and seg.label() == "left_hand=low"
    assert parse_control(live.result().config.control).frame_labels(len(motion))[t - 1] == ()


def test_frames_come_out_as_soon_as_their_speech_has_arrived(db, speech):
    """Step i is returned exactly when the window of the feature frame 14 frames after its start is in."""
    N, look, half = 8, LAYOUT.audio_lookahead, LAYOUT.n_fft - LAYOUT.n_fft // 2
    centres = frame_centres(len(speech) * 15 // SR + look + N)
    live = LiveSynthesizer(db)
    assert live.algorithmic_delay_s == pytest.approx(14 / 15 + 1024.5 / SR) and live.algorithmic_delay_s <= 1.0
    for pos in range(0, len(speech), 800):
        live.push(speech[pos : pos + 800])
        n_in = live.samples_in
        ready = 0
        while centres[ready * N + look] + half <= n_in and (ready + 1) * N <= n_in * 15 // SR:
            ready += 1
        assert live.frames_out == ready * N
        if ready:  # the last step out needed no more speech past its start than the stated delay
            t = (ready - 1) * N
            assert (centres[t + look] + half) / SR - t / 15 <= live.algorithmic_delay_s + 1e-9


def test_empty_pushes_change_nothing(db, speech):
    live = LiveSynthesizer(db)
    out = live.push(np.zeros(0, np.float32))
    assert out.shape == (0, 55, 3) and out.dtype == np.float32 and live.samples_in == 0
    live.push(speech[: 2 * SR])
    frames = live.frames_out
    assert live.push(np.zeros(0, np.float32)).shape == (0, 55, 3) and live.frames_out == frames


@pytest.mark.parametrize(
    "samples, problem",
    [
        (np.zeros(100, np.int16), "floats.*int16.*32768"),
        (np.zeros(100, np.complex64), "floats.*complex64"),
        (np.zeros((100, 2), np.float32), "mono.*\\(100, 2\\)"),
        (np.zeros((), np.float32), "mono"),
        (np.array([0.0, np.nan, 0.0], np.float32), "NaN or infinite.*sample 1"),
        (np.array([0.0, 0.0, np.inf]), "NaN or infinite.*sample 2"),
        ([0.0, 0.1], "numpy array.*list"),
    ],
    ids=["int16", "complex", "stereo", "scalar", "nan", "inf", "list"],
)
def test_bad_samples_are_refused_and_change_nothing(db, samples, problem):
    live = LiveSynthesizer(db)
    live.push(np.zeros(800, np.float32))
    with pytest.raises(ConfigError, match=problem):
        live.push(samples)
    assert live.samples_in == 800


@pytest.mark.parametrize(
    "control, problem",
    [
        ("left_hand=sideways", "left_hand.*takes"),
        ("elbow=high", "unknown control 'elbow'"),
        ("0-2:left_hand=high", "without times"),
        (3, "text.*int"),
    ],
)
def test_bad_controls_are_refused(db, control, problem):
    with pytest.raises(ConfigError, match=problem):
        LiveSynthesizer(db).set_control(control)


def test_after_finish_nothing_more_is_taken(db, speech):
    live = LiveSynthesizer(db)
    with pytest.raises(ConfigError, match="after finish"):
        live.result()
    live.push(speech[:SR])
    live.finish()
    for call in (lambda: live.finish(), lambda: live.push(speech[:10]), lambda: live.set_control(None)):
        with pytest.raises(ConfigError, match="has finished"):
            call()
    assert isinstance(live.result(), SynthesisResult) and live.finished


def test_speech_shorter_than_a_frame_is_refused_at_finish(db):
    live = LiveSynthesizer(db)
    live.push(np.zeros(1000, np.float32))
    with pytest.raises(ConfigError, match="shorter than one frame"):
        live.finish()


@pytest.mark.parametrize(
    "kwargs, problem",
    [
        ({"config": SynthesisConfig(pins={0: (0, 0)})}, "pins"),
        ({"config": {"k": 1}}, "SynthesisConfig"),
        ({"refiner": "demo"}, "refiner must be a loaded refiner"),
    ],
    ids=["pins", "dict-config", "refiner-name"],
)
def test_bad_options_are_refused(db, kwargs, problem):
    with pytest.raises(ConfigError, match=problem):
        LiveSynthesizer(db, **kwargs)


def test_result_round_trips_through_the_npz_export(db, speech, tmp_path):
    live, pieces, _ = stream(db, speech, [320], switches=[(SR, "right_hand=high")])
    res = live.result()
    path = save_result_npz(res, tmp_path / "live.npz")
    motion, arrays, meta = load_npz(path)
    np.testing.assert_array_equal(motion.positions, np.concatenate(pieces))
    np.testing.assert_array_equal(arrays["search_clip"], res.search.clip)
    loaded = SynthesisConfig.from_dict(meta["synthesis"])
    assert loaded == res.config and meta["control_segments"] == res.control.to_records()
    np.testing.assert_array_equal(synthesize(speech, db=db, config=loaded).motion.positions, motion.positions)


@pytest.mark.slow
def test_the_live_refiner_holds_back_its_stated_frames(db, speech):
    pytest.importorskip("torch")
    from gesturekit.refine import open_refiner

    refiner = open_refiner("demo")
    live = LiveSynthesizer(db, refiner=refiner)
    out = []
    for pos in range(0, len(speech), 3200):
        out.append(live.push(speech[pos : pos + 3200]))
        assert live.frames_out == max(0, live.frames_determined - live.REFINE_LOOKAHEAD)
    out.append(live.finish())
    res = live.result()
    motion = np.concatenate(out)
    assert motion.shape == (len(speech) * 15 // SR, 55, 3) and np.isfinite(motion).all()
    np.testing.assert_array_equal(res.motion.positions, motion)
    assert res.refined_motion is res.motion
    offline = synthesize(speech, db=db, refiner=refiner)
    np.testing.assert_array_equal(res.knn_motion.positions, offline.knn_motion.positions)
    # bounded windows: near the offline refiner, not equal to it
    assert np.abs(motion - offline.motion.positions).mean() < 0.05
    assert live.algorithmic_delay_s == pytest.approx(14 / 15 + 1024.5 / SR + 8 / 15)


def test_an_impossible_control_relaxes_as_offline(db, speech):
    switches = [(SR, "both_hands=high+speed=slow+width=narrow+symmetry=asymmetric"), (3 * SR, None)]
    with pytest.warns(GestureKitWarning, match="relaxed"):
        live, pieces, _ = stream(db, speech, [640], switches=switches)
    res, offline = check_equal_to_offline(db, speech, live, pieces)
    assert res.relaxed_steps and res.relaxed_steps == offline.relaxed_steps


@settings(max_examples=15, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    n_frames=st.integers(1, 40),
    segment=st.integers(1, 9),
    k=st.integers(0, 3),
    rule=st.sampled_from(["ends", "all"]),
    n_masks=st.integers(0, 3),
)
def test_a_search_step_by_step_equals_the_search_of_the_whole_query(seed, n_frames, segment, k, rule, n_masks):
    from gesturekit.search import SearchConfig, SearchIndex
    from gesturekit.search.stream import StepSearch

    rng = np.random.default_rng(seed)
    M, T = 12, 16
    P = rng.standard_normal((M, T, 96)).astype(np.float32)
    F = rng.standard_normal((M, T, 112)).astype(np.float32)
    valid = np.ones((M, T), bool)
    valid[:, -4:] = False
    query = rng.standard_normal((n_frames, 112)).astype(np.float32)
    masks = rng.random((n_masks, M, T)) < 0.6 if n_masks else None
    n_steps = -(-n_frames // segment)
    index_of_step = rng.integers(-1, n_masks, n_steps) if n_masks else None
    exclude = rng.random((M, T)) < 0.05
    cfg = SearchConfig(k=k, segment=segment, seed=seed % 97, mask_rule=rule)
    index = SearchIndex(P, F, valid)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        whole = index.search(query, config=cfg, masks=masks, step_mask_index=index_of_step, exclude=exclude)
        steps = StepSearch(index, cfg, exclude=exclude)
        ids = [steps.add_mask(m) for m in masks] if masks is not None else []
        for i in range(n_steps):
            j = -1 if index_of_step is None or index_of_step[i] < 0 else ids[index_of_step[i]]
            steps.step(query[i * segment], j, min(segment, n_frames - i * segment))
        streamed = steps.result()
    steps.close()
    assert streamed.equals(whole)


@pytest.mark.parametrize("then", ["right_hand=high", None])
def test_a_switch_cuts_the_configurations_control_track(db, speech, then):
    config = SynthesisConfig(control="0.5-4.5:left_hand=low")
    live, pieces, before = stream(db, speech, [480], config=config, switches=[(int(2.2 * SR), then)])
    res, _ = check_equal_to_offline(db, speech, live, pieces, config)
    first = res.control.segments[0]
    assert (first.start_s, first.label()) == (0.5, "left_hand=low") and round(first.end_s * 15) == before[0]
    assert [s.label() for s in res.control.segments[1:]] == ([then] if then else [])


def test_controls_switched_from_another_thread_are_recorded_as_they_acted(db, speech):
    import threading
    import time

    live = LiveSynthesizer(db)
    stop = threading.Event()

    def clicks():
        for i in range(200):
            if stop.is_set():
                return
            live.set_control(["left_hand=high", None, "speed=slow"][i % 3])
            time.sleep(0.002)

    clicker = threading.Thread(target=clicks)
    clicker.start()
    pieces = []
    try:
        for pos in range(0, len(speech), 320):
            pieces.append(live.push(speech[pos : pos + 320]))
            time.sleep(0.0005)
    finally:
        stop.set()
        clicker.join()
    pieces.append(live.finish())
    check_equal_to_offline(db, speech, live, pieces)


def test_a_synthesizer_dropped_before_finish_leaves_no_thread_behind(db, speech):
    import gc
    import threading

    def search_threads():
        return [t for t in threading.enumerate() if t.name.startswith("ThreadPoolExecutor")]

    before = set(search_threads())
    live = LiveSynthesizer(db)
    live.push(speech[: 3 * 16000])
    assert live.frames_out > 0
    del live
    gc.collect()
    wait_until(lambda: not set(search_threads()) - before, what="the search threads have ended", timeout_s=120)
