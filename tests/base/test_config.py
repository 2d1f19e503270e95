"""One JSON form for every configuration dataclass (gesturekit._config): written from the fields,
read back to equal objects, unknown options refused with the class's own words."""

from __future__ import annotations

import dataclasses
import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gesturekit._config import config_from_dict, config_to_dict
from gesturekit.datasets.presets import PRESETS, JointMap
from gesturekit.errors import ConfigError
from gesturekit.refine.data import PairsConfig
from gesturekit.refine.model import ModelConfig
from gesturekit.refine.train import TrainConfig
from gesturekit.search import SearchConfig
from gesturekit.synthesis import SynthesisConfig

names = st.text("abcdefghij_", min_size=1, max_size=8)
ranges = st.tuples(names, st.floats(0, 49), st.floats(50, 100))  # start < end

# the configurations with options that earlier versions saved under other names
RENAMED = st.one_of(
    st.builds(
        PairsConfig,
        seed=st.integers(0, 99),
        segment=st.integers(1, 16),
        k_max=st.integers(2, 20),
        exclude_takes=st.lists(names, max_size=3).map(tuple),
        exclude_ranges=st.lists(ranges, max_size=3).map(tuple),
    ),
    st.builds(
        SearchConfig,
        k=st.integers(0, 9),
        segment=st.integers(1, 16),
        record=st.integers(1, 20),
        init_pose=st.one_of(st.just("random"), st.lists(st.floats(-5, 5), min_size=1, max_size=6).map(tuple)),
        pins=st.dictionaries(st.integers(0, 9), st.tuples(st.integers(0, 9), st.integers(0, 9)), max_size=3),
    ),
)
CONFIGS = st.one_of(
    st.builds(
        ModelConfig,
        generator_channels=st.tuples(*[st.integers(1, 512)] * 4),
        critic_channels=st.tuples(*[st.integers(1, 512)] * 3),
    ),
    st.builds(
        TrainConfig,
        iterations=st.integers(1, 10**6),
        betas=st.tuples(st.floats(0, 0.99), st.floats(0, 0.99)),
        seed=st.integers(0, 99),
    ),
    RENAMED,
    st.builds(
        SynthesisConfig,
        k=st.integers(0, 9),
        init=st.sampled_from(["random", "rest"]),
        exclude_takes=st.lists(names, max_size=3).map(tuple),
        exclude_ranges=st.lists(ranges, max_size=3).map(tuple),
        control=st.sampled_from(["", "0-3:left_hand=low", "1-2:speed=fast+width=wide,4-6:symmetry=symmetric"]),
    ),
)


@settings(max_examples=150, deadline=None)
@given(CONFIGS)
def test_every_config_reads_back_from_its_json(config):
    saved = json.loads(json.dumps(config.to_dict()))  # through text, as it is saved
    assert type(config).from_dict(saved) == config


@pytest.mark.parametrize(
    "cls, words",
    [
        (ModelConfig, "unknown model options: extra"),
        (TrainConfig, "unknown training options: extra"),
        (PairsConfig, "unknown training-data options: extra"),
        (SearchConfig, "unknown SearchConfig keys: extra"),
        (SynthesisConfig, "unknown synthesis options: extra"),
    ],
)
def test_unknown_options_are_refused_by_name(cls, words):
    with pytest.raises(ConfigError, match=words):
        cls.from_dict({**cls().to_dict(), "extra": 1})


def test_a_joint_map_is_written_without_its_name():
    preset = next(iter(PRESETS.values()))
    d = json.loads(json.dumps(preset.to_dict()))
    assert set(d) == {"pelvis", "joints"} and JointMap(name=preset.name, **d) == preset


@dataclasses.dataclass(frozen=True)
class _Inner:
    pair: tuple = (0, 0)


@dataclasses.dataclass(frozen=True)
class _Outer:
    inner: _Inner = dataclasses.field(default_factory=_Inner)
    n: int = 0


@settings(max_examples=50, deadline=None)
@given(st.tuples(st.integers(), st.integers()), st.integers())
def test_a_nested_configuration_without_its_own_reader_is_read_by_its_fields(pair, n):
    config = _Outer(_Inner(pair), n)
    saved = json.loads(json.dumps(config_to_dict(config)))
    assert config_from_dict(_Outer, saved, what="outer options") == config


def test_a_nested_configuration_refuses_unknown_options_in_the_outer_words():
    with pytest.raises(ConfigError, match="unknown outer options: extra"):
        config_from_dict(_Outer, {"inner": {"extra": 1}}, what="outer options")


def test_only_a_dataclass_is_read_from_a_json_form():
    with pytest.raises(TypeError, match="not a dataclass"):
        config_from_dict(dict, {}, what="options")


OLD_NAMES = {"init": "init_pose", "step": "segment", "topk": "record"}


@settings(max_examples=60, deadline=None)
@given(RENAMED)
def test_configs_saved_under_earlier_names_read_back(config):
    saved = json.loads(json.dumps(config.to_dict()))
    old = {next((o for o, n in OLD_NAMES.items() if n == name), name): value for name, value in saved.items()}
    assert old != saved  # N was "step" in every one of them
    assert type(config).from_dict(old) == config


def test_the_shipped_demo_refiners_data_options_read_back():
    # saved before N was called "segment": a resumed training must still see the same options
    from importlib import resources

    saved = json.loads((resources.files("gesturekit") / "assets" / "demo-refiner" / "config.json").read_text())
    assert "step" in saved["data"]
    data = PairsConfig.from_dict(saved["data"])
    assert data == PairsConfig(segment=saved["data"]["step"], seed=saved["data"]["seed"])
    assert "segment" in data.to_dict() and "step" not in data.to_dict()
