"""One source for every option: the CLI's flags and the app's widgets are the configurations' fields.

Every option of the commands that run a configuration, and every widget of the app that sets
one, names exactly one field declared with :func:`gesturekit.options.option`, and says its
default, bounds and choices; an option or widget with no field, or with its own default or
range, fails here.
"""

from __future__ import annotations

import argparse
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from gesturekit.cli._options import FIELD_OF, OPTIONS_DEST, options_given
from gesturekit.cli._parser import build_parser
from gesturekit.database import BuildConfig, MatchingDatabase
from gesturekit.errors import ConfigError
from gesturekit.evaluate.fgd import FGDConfig
from gesturekit.evaluate.run import EvaluationConfig
from gesturekit.options import check_option, default_of, option_of, options_of, widget_limits
from gesturekit.refine.train import TrainConfig
from gesturekit.search import SearchConfig
from gesturekit.study.stimuli import StudyConfig
from gesturekit.synthesis import SynthesisConfig
from tests.waits import APP_RUN_S

TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)

#: The options of each command that are no configuration's: what to read and write, and how to run.
RUN_ARGUMENTS = {
    "build-db": {
        "folder",
        "out",
        # how the takes are read: ReadOptions and build_database's arguments, recorded with the database
        "preset",
        "joint_map",
        "kind",
        "fps",
        "units",
        "up",
        "forward",
        "no_plausibility_check",
        "allow_duration_mismatch",
        "normalize_bones",
        # how the build runs (the database is the same for any), and what it does with one there
        "force",
        "workers",
        "scheduler",
        "append",
        "keep_stats",
        # the generated demo speaker's takes (build_demo_database's arguments), not a build option
        "demo",
        "minutes",
        "seed",
    },
    "synthesize": {
        "speech",
        "db",
        "out",
        "control",  # a track's text or a file, read into SynthesisConfig.control
        "exclude_take",
        "exclude_range",
        "refiner",
        "search_device",  # where the search runs (the same motion on any): how it runs, as --workers
        "format",
        "character",
        "character_map",
        "character_clips",  # what the character's GLB keeps of the file's own clips: a run argument, as the map
        "wrist_slack",  # Character.wrist_slack, read with the character as its map is
        "video",
        "video_style",
        "video_full_body",  # RenderStyle.framing of the MP4
        "force",
        "max_speech_minutes",
    },
    "evaluate": {"db", "out", "force"},
    "stimuli": {"db", "out", "force", "max_speech_minutes"},
    "train-fgd": {"db", "out", "holdout", "force"},
    "train-refiner": {
        "db",
        "demo",
        "out",
        "preset",
        "iterations",  # the preset's (quick or paper) TrainConfig.iterations unless given
        "resume",
        "device",
        "exclude_take",
        "exclude_range",
        "no_train_state",
        "force",
    },
}

#: Commands whose options are no configuration's, and why.
NOT_OPTIONS_COMMANDS = {
    "info": "reads a database; no options",
    "study": "its subcommands run a study folder; no configuration",
    "app": "serves the app: an address, a port and folders, Streamlit's settings; no configuration",
}

CONFIGS = (SearchConfig, SynthesisConfig, TrainConfig, StudyConfig, EvaluationConfig, FGDConfig, BuildConfig)


def _commands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _cli_default(cls: type, name: str):
    """The field's default as the command line holds it before parsing."""
    opt = option_of(cls, name)
    default = default_of(cls, name)
    if isinstance(default, bool):  # a switch: its flag gives the other value
        return default
    if opt.nargs or opt.append:
        return None  # not given: the field's empty default
    if isinstance(default, tuple):
        return ("x" if all(isinstance(v, int) for v in default) else ",").join(map(str, default))
    return default


def test_every_command_is_covered_or_says_why_not():
    assert set(_commands()) == set(RUN_ARGUMENTS) | set(NOT_OPTIONS_COMMANDS)


@pytest.mark.parametrize("command", sorted(RUN_ARGUMENTS))
def test_every_cli_option_is_one_field_with_its_default_bounds_and_choices(command):
    parser = _commands()[command]
    seen: dict[tuple[type, str], str] = {}
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        field = getattr(action, FIELD_OF, None)
        if field is None:
            assert action.dest in RUN_ARGUMENTS[command], f"{command} {action.option_strings}: no field"
            continue
        assert action.dest not in RUN_ARGUMENTS[command]
        cls, name = field
        assert field not in seen, f"{command}: {action.option_strings} and {seen[field]} set {cls.__name__}.{name}"
        seen[field] = action.option_strings[0]
        opt = option_of(cls, name)
        assert action.dest == name
        if action.required:  # a field without default (EvaluationConfig.holdout)
            with pytest.raises(KeyError):
                default_of(cls, name)
        else:
            assert action.default == _cli_default(cls, name), f"{command} {action.option_strings}: another default"
        assert list(action.choices or []) == list(opt.choices or []), f"{command} {action.option_strings}"
        switch = not action.required and isinstance(default_of(cls, name), bool)
        assert (opt.switch_help if switch and opt.switch_help else opt.help) in action.help or (
            command == "evaluate" and name == "seed"
        )
        if switch:  # its flag (--no-audio) stores the other value than the field's default
            assert action.nargs == 0 and action.const is (not default_of(cls, name)), command
        elif opt.kind is not None:
            assert action.type is opt.kind
        elif opt.choices is None and not isinstance(default_of(cls, name), tuple):
            assert action.type is type(default_of(cls, name))
    assert parser.get_default(OPTIONS_DEST) == list(seen)


def _parse(command: str, action: argparse.Action, value: str) -> argparse.Namespace:
    """``command`` with its required arguments and ``value`` for ``action``'s option (each of its values)."""
    required = {"synthesize": ["s.wav"], "evaluate": ["--holdout", "t"], "stimuli": ["--out", "o"]}
    required["train-refiner"] = required["train-fgd"] = ["--out", "o"]
    required["build-db"] = ["takes", "--out", "o"]
    flag = action.option_strings[0]
    given = [flag, *[value] * action.nargs] if isinstance(action.nargs, int) else [f"{flag}={value}"]
    return build_parser().parse_args([command, *required[command], *given])


@pytest.mark.parametrize("command", sorted(RUN_ARGUMENTS))
def test_every_bounded_cli_option_refuses_a_value_out_of_its_fields_bounds(command):
    checked = 0
    for action in _commands()[command]._actions:
        field = getattr(action, FIELD_OF, None)
        if field is None or option_of(*field).choices is not None or action.nargs == 0:
            continue
        opt = option_of(*field)
        flag = action.option_strings[0]
        several = isinstance(action.nargs, int)  # each value within the bounds (--percentiles LOW HIGH)
        if opt.low is not None:
            below = opt.low - (0 if opt.low_open else 1)
            with pytest.raises(ConfigError, match=f"^{flag} must be "):
                options_given(_parse(command, action, f"{below:g}"))
            checked += 1
            at_low = opt.low + (0.5 if action.type is float else 1) * opt.low_open  # the lowest value taken
            got = options_given(_parse(command, action, f"{at_low:g}"))[field[0]][field[1]]
            assert got == ((at_low,) * action.nargs if several else at_low)
        if opt.high is not None:
            with pytest.raises(ConfigError, match=f"^{flag} must be "):
                options_given(_parse(command, action, f"{opt.high + 1:g}"))
        if action.type is float:
            with pytest.raises(ConfigError, match=f"^{flag} must be "):
                options_given(_parse(command, action, "nan"))
    assert checked


def test_options_given_tells_the_options_given_from_those_left_at_their_defaults():
    """``build-db --append`` keeps the database's options for those left out: it must know which were given."""
    parser = build_parser()
    left_out = parser.parse_args(["build-db", "takes", "--out", "o", "--append"])
    assert options_given(left_out, only_given=True)[BuildConfig] == {}
    assert options_given(left_out)[BuildConfig]["audio_rate"] == default_of(BuildConfig, "audio_rate")
    # a value equal to the default, given, is given
    args = ["build-db", "takes", "--out", "o", "--append", "--percentiles", "15", "85", "--no-audio", "--label", "x"]
    given = options_given(parser.parse_args(args), only_given=True)[BuildConfig]
    assert given == {"percentiles": (15.0, 85.0), "store_audio": False, "label": "x"}
    # a second parse starts with nothing given
    assert options_given(parser.parse_args(["build-db", "t", "--out", "o"]), only_given=True)[BuildConfig] == {}


@given(st.data())
def test_check_option_takes_exactly_the_values_within_the_bounds(data):
    cls = data.draw(st.sampled_from(CONFIGS))
    numeric = [
        n
        for n, o in options_of(cls).items()
        if (o.low is not None or o.high is not None) and not isinstance(default_of(cls, n), (tuple, bool))
    ]
    if not numeric:
        return
    name = data.draw(st.sampled_from(numeric))
    opt = option_of(cls, name)
    integer = (opt.kind or type(default_of(cls, name))) is int
    value = data.draw(st.integers(-1000, 1000) if integer else st.floats(allow_nan=True, allow_infinity=True))
    inside = (
        math.isfinite(value)
        and (opt.low is None or value > opt.low or (value == opt.low and not opt.low_open))
        and (opt.high is None or value <= opt.high)
    )
    if inside:
        assert check_option(cls, name, value) == value
    else:
        with pytest.raises(ConfigError, match=f"{cls.__name__}.{name} must be"):
            check_option(cls, name, value)


def test_every_field_default_is_within_its_own_bounds_and_choices():
    for cls in CONFIGS:
        for name, opt in options_of(cls).items():
            try:
                default = default_of(cls, name)
            except KeyError:  # a required option (EvaluationConfig.holdout)
                continue
            if opt.choices is not None:
                assert default in opt.choices
            else:
                assert check_option(cls, name, default) == default


# ---- the app ------------------------------------------------------------------------------------

#: Widgets of the pages (their key after ``_w.``) that set no configuration option, and what they set.
NOT_OPTIONS = {
    "synth.mode": "where the speech comes from",
    "synth.example": "which example speech",
    "synth.refine": "whether a refiner is used",
    "synth.refiner_path": "the refiner's folder, opened by the page (the synthesis takes the refiner itself)",
    "study.folder": "a folder of speech files, listed into StudyConfig.audio with the uploads",
    "study.out": "the study folder to write (make_stimuli's out, no option)",
    "study.resolution": "a choice of sizes of StudyConfig.resolution (its default checked below)",
}


def _fields_of(page_key: str) -> tuple[type, str]:
    page, name = page_key.split(".", 1)
    classes = (SearchConfig, SynthesisConfig) if page == "synth" else (StudyConfig,)
    owners = [cls for cls in classes if name in options_of(cls)]
    assert len(owners) == 1, f"widget {page_key}: {len(owners)} fields named {name}"
    return owners[0], name


def _open(page: str) -> AppTest:
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.switch_page(page).run()
    assert not at.exception, at.exception
    return at


@pytest.mark.slow
@pytest.mark.parametrize("page, prefix", [("views/1_Synthesize.py", "synth."), ("views/4_Study_stimuli.py", "study.")])
def test_every_app_widget_that_sets_an_option_has_its_fields_limits_and_default(app_env, page, prefix):
    db = MatchingDatabase.load(app_env / "db" / "demo")
    at = _open(page)
    checked = set()
    for kind in ("number_input", "selectbox", "multiselect", "slider", "toggle", "checkbox", "text_input"):
        for widget in at.get(kind):
            key = widget.key
            if not key or not key.startswith("_w." + prefix):
                continue
            page_key = key.removeprefix("_w.")
            if page_key in NOT_OPTIONS:
                continue
            cls, name = _fields_of(page_key)
            lim = widget_limits(cls, name, context=db)
            if kind == "number_input":
                assert (widget.min, widget.max) == (lim["min"], lim["max"]), page_key
                assert widget.step == lim["step"], page_key
            if kind == "selectbox":
                assert len(widget.options) == len(lim["choices"]), page_key
            if kind == "text_input":  # an empty box: the field's empty default (None, "" or ()); free text
                assert widget.value == "" and lim["default"] in (None, "", ()), page_key
            elif kind == "multiselect":  # the field's start (StudyConfig.systems: what needs no holdout)
                assert tuple(widget.value) == tuple(lim["start"]), page_key
            else:
                assert widget.value == lim["default"] == lim["start"], page_key
            # the field's help first; a page may add what an empty box means or what each choice is
            assert widget.help.startswith(lim["help"]), page_key
            checked.add(page_key)
    expected = {
        "synth.": {f"synth.{n}" for n in ("k", "segment", "seed", "record", "init", "blend", "mask_rule")}
        | {"synth.refiner_keep_hz"},
        "study.": {"study.seed", "study.participants", "study.workers", "study.holdouts", "study.control"}
        | {"study.systems"},
    }[prefix]
    assert checked == expected
    if prefix == "study.":
        default = "x".join(map(str, default_of(StudyConfig, "resolution")))
        assert at.selectbox(key="_w.study.resolution").value == default


def test_an_option_starts_elsewhere_in_the_app_only_where_its_field_says_so():
    starts = {(cls, n): o.start for cls in CONFIGS for n, o in options_of(cls).items() if o.start is not None}
    assert set(starts) == {(StudyConfig, "systems")}
    # the study page's start needs neither a held-out part nor a refiner, and differs from the CLI's default
    assert not {"gt", "knn+cgan"} & set(starts[StudyConfig, "systems"])
    assert widget_limits(StudyConfig, "systems")["start"] != default_of(StudyConfig, "systems")
    assert widget_limits(SearchConfig, "k")["start"] == default_of(SearchConfig, "k")


#: Widgets of the sidebar's build form (their key after ``_gk.build_``) that set no BuildConfig field, and what.
BUILD_NOT_OPTIONS = {
    "folder": "the folder of takes (build_database's folder)",
    "naming": "the joint naming preset or a joint map (build_database's joint_map)",
    "map": "the joint map's file",
    "fps": "the frame rate of joint-position files (how the takes are read)",
    "units": "how the takes are read",
    "up": "how the takes are read",
    "forward": "how the takes are read",
    "bones": "how the takes are read (normalize_bones)",
    "out": "the database folder to write",
    "workers": "how the build runs (the database is the same for any number)",
    "overwrite": "whether an existing database is replaced",
    "go": "the button",
}


@pytest.mark.slow
def test_every_build_widget_of_the_sidebar_that_sets_an_option_has_its_fields_limits_and_default(app_env):
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    assert not at.exception, at.exception
    checked, others = set(), set()
    for kind in ("number_input", "selectbox", "multiselect", "slider", "toggle", "checkbox", "text_input", "radio"):
        for widget in at.sidebar.get(kind):
            key = widget.key or ""
            if key.startswith("_gk.build_"):
                others.add(key.removeprefix("_gk.build_"))
            if not key.startswith("_gk.build."):
                continue
            name = key.removeprefix("_gk.build.")
            lim = widget_limits(BuildConfig, name)
            if kind == "number_input":
                assert (widget.min, widget.max, widget.step) == (lim["min"], lim["max"], lim["step"]), name
            assert widget.value == lim["default"] and widget.help == lim["help"], name
            checked.add(name)
    assert checked == {"label"}
    assert others == set(BUILD_NOT_OPTIONS) - {"map", "go"}  # the map's box shows with a JSON joint map
