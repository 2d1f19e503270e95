import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit.control import (
    ATTRIBUTE_NAMES,
    CONSTRAINTS,
    ControlTrack,
    Segment,
    constraint_mask,
    frame_attributes,
    load_control_file,
    parse_control,
    parse_time_range,
    step_masks,
)
from gesturekit.errors import ConfigError, InputFileError
from gesturekit.skeleton import N_JOINTS, joint_index


def _pose(n=30):
    pos = np.zeros((n, N_JOINTS, 3), np.float32)
    pos[:, joint_index("upper_chest")] = [0.0, 0.4, 0.0]
    return pos


def test_attributes_of_known_motion():
    pos = _pose()
    t = np.arange(30) / 15.0
    lw, rw = joint_index("left_wrist"), joint_index("right_wrist")
    pos[:, lw] = np.stack([0.3 + 0 * t, 0.2 + 0.15 * t, 0.1 + 0 * t], 1)  # rises at 0.15 m/s
    pos[:, rw] = [-0.3, 0.2, 0.1]  # still, mirror image of the left wrist at t=0
    a = frame_attributes(pos)
    col = {n: a[:, i] for i, n in enumerate(ATTRIBUTE_NAMES)}
    np.testing.assert_allclose(col["left_hand_height"], 0.2 + 0.15 * t, atol=1e-6)
    np.testing.assert_allclose(col["left_hand_speed"], 0.15, atol=1e-5)
    np.testing.assert_allclose(col["right_hand_speed"], 0.0, atol=1e-7)
    np.testing.assert_allclose(col["hand_speed"], 0.075, atol=1e-5)
    np.testing.assert_allclose(col["left_hand_width"], np.hypot(0.3, 0.1), atol=1e-6)
    np.testing.assert_allclose(col["asymmetry"], 0.15 * t, atol=1e-6)  # symmetric at t=0


def test_parse_control_text():
    tr = parse_control("0-3:left_hand=low, 3-6:speed=slow+symmetry=symmetric,6-9.5:right_hand=high")
    assert [(s.start_s, s.end_s) for s in tr.segments] == [(0, 3), (3, 6), (6, 9.5)]
    assert tr.segments[1].constraints == (("speed", "slow"), ("symmetry", "symmetric"))
    assert parse_control(tr.to_text()) == tr
    assert not parse_control("")


def test_a_track_snapped_to_steps_reads_short_for_a_person_and_whole_for_the_command_line():
    tr = parse_control(f"{56 / 15:.6f}-{96 / 15:.6f}:both_hands=high,{1 / 3:.6f}-1:speed=fast")
    assert tr.to_text(decimals=2) == "0.33-1:speed=fast,3.73-6.4:both_hands=high"  # in time order
    assert tr.to_text() == "0.333333-1:speed=fast,3.733333-6.4:both_hands=high"
    assert parse_control(tr.to_text()) == tr  # the full form reads back; the short one is for reading


@pytest.mark.parametrize(
    "text, message",
    [
        ("0-3:left_hand=middle", "takes low or high"),
        ("0-3:elbow=low", "unknown control 'elbow'"),
        ("3-1:speed=slow", "end must be after start"),
        ("0-3 speed=slow", "START-END:name=value"),
        ("0-3:speed=slow,2-4:width=wide", "overlap"),
        ("0-3:speed=slow+speed=fast", "twice"),
    ],
)
def test_parse_control_errors(text, message):
    with pytest.raises(ConfigError, match=message):
        parse_control(text)


_segment = st.builds(
    lambda a, d, names, vals: (a, d, names, vals),
    st.integers(0, 50),
    st.integers(1, 20),
    st.lists(st.sampled_from(sorted(CONSTRAINTS)), min_size=1, max_size=3, unique=True),
    st.randoms(use_true_random=False),
)


@settings(max_examples=50, deadline=None)
@given(st.lists(_segment, max_size=5))
def test_text_and_csv_round_trip(raw):
    segs, t = [], 0.0
    for a, d, names, rnd in raw:
        start = t + a / 10
        cons = tuple((n, rnd.choice(sorted(CONSTRAINTS[n][1]))) for n in names)
        segs.append(Segment(start, start + d / 4, cons))
        t = start + d / 4
    tr = ControlTrack(tuple(segs))
    assert parse_control(tr.to_text()) == tr
    import csv
    import io

    assert ControlTrack.from_records(list(csv.DictReader(io.StringIO(tr.to_csv())))) == tr


def test_control_files(tmp_path):
    (tmp_path / "c.csv").write_text("start_s,end_s,constraint\n0,3,left_hand=high\n3,6,speed=fast+width=wide\n")
    tr = load_control_file(tmp_path / "c.csv")
    assert tr.to_text() == "0-3:left_hand=high,3-6:speed=fast+width=wide"
    (tmp_path / "c.json").write_text(json.dumps(tr.to_records()))
    assert load_control_file(tmp_path / "c.json") == tr
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(InputFileError, match="bad.json: not valid JSON"):
        load_control_file(tmp_path / "bad.json")
    (tmp_path / "bad.csv").write_text("start_s,end_s,constraint\n0,3,left_hand=sideways\n")
    with pytest.raises(InputFileError, match="bad.csv"):
        load_control_file(tmp_path / "bad.csv")
    with pytest.raises(InputFileError, match="missing.csv"):
        load_control_file(tmp_path / "missing.csv")


def test_constraint_mask_and_combination():
    rng = np.random.default_rng(0)
    attrs = rng.normal(size=(5, 64, len(ATTRIBUTE_NAMES))).astype(np.float32)
    thr = {n: (-0.5, 0.5) for n in ATTRIBUTE_NAMES}
    lh = attrs[..., ATTRIBUTE_NAMES.index("left_hand_height")]
    sp = attrs[..., ATTRIBUTE_NAMES.index("hand_speed")]
    np.testing.assert_array_equal(constraint_mask(attrs, (("left_hand", "high"),), thr), lh > 0.5)
    np.testing.assert_array_equal(
        constraint_mask(attrs, (("left_hand", "low"), ("speed", "fast")), thr), (lh < -0.5) & (sp > 0.5)
    )
    rh = attrs[..., ATTRIBUTE_NAMES.index("right_hand_height")]
    np.testing.assert_array_equal(constraint_mask(attrs, (("both_hands", "high"),), thr), (lh > 0.5) & (rh > 0.5))


def test_step_masks_use_each_steps_middle_frame():
    attrs = np.zeros((2, 64, len(ATTRIBUTE_NAMES)), np.float32)
    thr = {n: (0.5, 0.5) for n in ATTRIBUTE_NAMES}  # every frame is "low", none is "high"
    # 0-1 s = frames 0..14 low left hand; steps of 8: [0,8) mid 3, [8,16) mid 11, [16,24) mid 19
    tr = parse_control("0-1:left_hand=low,2-3:speed=fast")
    masks, idx = step_masks(tr, attrs, thr, n_frames=45, segment=8)
    # [32,40) mid 35 and [40,45) mid 42 lie in 2-3 s (frames 30..44)
    assert list(idx) == [0, 0, -1, -1, 1, 1]
    assert masks.shape == (2, 2, 64) and masks[0].all() and not masks[1].any()
    masks, idx = step_masks(ControlTrack(()), attrs, thr, n_frames=45, segment=8)
    assert masks is None and (idx == -1).all()


_decimal = st.decimals(min_value=0, max_value=10**6, allow_nan=False, allow_infinity=False, places=3)


@settings(max_examples=80, deadline=None)
@given(_decimal, _decimal)
def test_time_range_accepts_plain_decimals_with_start_before_end(a, b):
    text = f"{a}-{b}"
    if a < b:
        assert parse_time_range(text) == (float(a), float(b))
    else:
        with pytest.raises(ConfigError, match="end must be after start"):
            parse_time_range(text)


@pytest.mark.parametrize(
    "text", ["1..2-3", "nan-3", "0-inf", "1e3-2e3", "-1-2", "+1-2", "1-", "-", "1 2-3", "", "0x1-2", "1_0-20"]
)
def test_time_range_refuses_what_is_not_two_plain_numbers(text):
    with pytest.raises(ConfigError, match="START-END in seconds"):
        parse_time_range(text)


def test_time_range_too_large_to_be_seconds():
    with pytest.raises(ConfigError, match="too large"):
        parse_time_range("0-" + "9" * 400)


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet=st.sampled_from("0123456789.-:,+=e nafilt_hghwsowd"), max_size=40) | st.text(max_size=40))
def test_parse_control_raises_only_config_errors(text):
    try:
        track = parse_control(text)
    except ConfigError:
        return
    assert all(0 <= s.start_s < s.end_s and np.isfinite(s.end_s) for s in track.segments)


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=120), st.sampled_from(["c.csv", "c.json"]))
def test_control_file_of_any_bytes_is_read_or_refused_by_name(tmp_path_factory, data, name):
    f = tmp_path_factory.mktemp("ctl") / name
    f.write_bytes(data)
    try:
        track = load_control_file(f)
    except InputFileError as exc:
        assert exc.path == str(f)
        return
    assert isinstance(track, ControlTrack)


@pytest.mark.parametrize(
    "name, content, message",
    [
        ("c.csv", "start_s,end_s,constraint\n0,1,left_hand=h\xe9\n".encode("latin-1"), "not UTF-8"),
        ("c.json", b"42", "must hold a list of segments"),
        ("c.json", b'{"segments": "0-1:left_hand=high"}', "must hold a list of segments"),
        ("c.json", b'[["0", "1", "left_hand=high"]]', "row 1 must be an object"),
        ("c.json", b'[{"start_s": 0, "end_s": 1, "constraint": "left_hand=high"}, {"start_s": 2}]', "row 2 needs"),
        ("c.json", b'[{"start_s": 1, "end_s": 0.5, "constraint": "left_hand=high"}]', "row 1: .*end must be after"),
        ("c.csv", b"start,end,constraint\n0,1,left_hand=high\n", "missing start_s, end_s"),
        ("c.csv", b"", "no header"),
    ],
)
def test_control_file_structure_errors(tmp_path, name, content, message):
    f = tmp_path / name
    f.write_bytes(content)
    with pytest.raises(InputFileError, match=message) as info:
        load_control_file(f)
    assert info.value.path == str(f) and str(info.value).count(str(f)) == 1
