import subprocess
import sys

import numpy as np
import pytest
import soundfile as sf

from gesturekit.cli import main
from gesturekit.database import MatchingDatabase
from tests.conftest import make_take
from tests.waits import patience


def _positions_folder(tmp_path):
    """A folder of two joint-position takes with speech and a JSON joint map."""
    import json

    from gesturekit.skeleton import JOINT_NAMES

    folder = tmp_path / "takes"
    folder.mkdir()
    for i in range(2):
        take = make_take(9.0, seed=i, fps=30.0)
        np.save(folder / f"t{i}.npy", take.motion.positions)
        sf.write(folder / f"t{i}.wav", take.audio, 16000, subtype="PCM_16")
    jm = tmp_path / "map.json"
    jm.write_text(json.dumps({"pelvis": None, "joints": {n: i for i, n in enumerate(JOINT_NAMES)}}))
    return folder, jm


@pytest.mark.slow
def test_build_and_info_from_position_files(tmp_path, capsys):
    folder, jm = _positions_folder(tmp_path)
    out = tmp_path / "db"
    assert (
        main(
            [
                "build-db",
                str(folder),
                "--joint-map",
                str(jm),
                "--fps",
                "30",
                "--up",
                "y",
                "--forward",
                "z",
                "--units",
                "m",
                "--no-plausibility-check",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "takes      2" in printed and "clips      4 x 64 frames" in printed and "built in" in printed
    db = MatchingDatabase.load(out)
    assert db.take_names == ["t0", "t1"] and db.n_clips == 4  # 9 s at 15 fps = 135 frames = 2 clips each
    assert main(["info", str(out), "--takes"]) == 0
    printed = capsys.readouterr().out
    assert "t1" in printed and "left_hand_height" in printed
    # every attribute's line ends in its unit
    lines = {ln.split()[0]: ln.split()[-1] for ln in printed.splitlines() if ln.startswith("  ")}
    assert lines["left_hand_height"] == "m" and lines["hand_speed"] == "m/s" and lines["asymmetry"] == "m"


def test_errors_are_one_line_with_exit_status_2(tmp_path, capsys):
    assert main(["build-db", str(tmp_path / "nope"), "--preset", "zeggs", "--out", str(tmp_path / "db")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gesturekit: error: ") and "nope: no such folder" in err and "Traceback" not in err
    assert main(["info", str(tmp_path / "missing-db")]) == 2
    assert "no database folder" in capsys.readouterr().err


def test_an_absent_search_device_is_said_before_any_work(tmp_path, capsys):
    pytest.importorskip("torch")
    speech = tmp_path / "speech.wav"
    sf.write(speech, np.zeros(16000, np.float32), 16000)
    out = tmp_path / "out"
    assert main(["synthesize", str(speech), "--out", str(out), "--search-device", "nowhere:7"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gesturekit: error: search device 'nowhere:7' is not a torch device") and not out.exists()


@pytest.mark.slow
def test_existing_database_needs_force(tmp_path, capsys):
    folder, jm = _positions_folder(tmp_path)
    out = tmp_path / "db"
    args = [
        "build-db",
        str(folder),
        "--joint-map",
        str(jm),
        "--fps",
        "30",
        "--up",
        "y",
        "--forward",
        "z",
        "--units",
        "m",
        "--no-plausibility-check",
        "--out",
        str(out),
    ]
    assert main(args) == 0
    assert main(args) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(args + ["--force"]) == 0


def test_position_files_need_joint_map_and_fps(tmp_path, capsys):
    folder, _ = _positions_folder(tmp_path)
    assert main(["build-db", str(folder), "--out", str(tmp_path / "db")]) == 2
    assert "--joint-map" in capsys.readouterr().err


def test_python_dash_m_runs_the_cli():
    r = subprocess.run(
        [sys.executable, "-m", "gesturekit", "--help"], capture_output=True, text=True, timeout=patience(300)
    )
    assert r.returncode == 0 and "build-db" in r.stdout


def test_an_os_error_while_reading_is_one_message_naming_the_file(monkeypatch, capsys):
    import gesturekit.cli as cli

    def read_fails(args):
        raise IsADirectoryError(21, "Is a directory", "/data/takes/t.wav")

    monkeypatch.setattr(cli, "_cmd_info", read_fails)
    assert cli.main(["info", "somewhere"]) == 2
    assert capsys.readouterr().err == "gesturekit: error: /data/takes/t.wav: Is a directory\n"

    def copy_fails(args):
        raise OSError(5, "Input/output error", "/a/in.npy", None, "/b/out.npy")

    monkeypatch.setattr(cli, "_cmd_info", copy_fails)
    assert cli.main(["info", "somewhere"]) == 2
    assert capsys.readouterr().err == "gesturekit: error: /a/in.npy -> /b/out.npy: Input/output error\n"


def test_a_bug_is_not_hidden_behind_a_message(monkeypatch):
    import gesturekit.cli as cli

    def bug(args):
        return {}["missing"]

    monkeypatch.setattr(cli, "_cmd_info", bug)
    with pytest.raises(KeyError):
        cli.main(["info", "somewhere"])


def test_long_user_text_is_never_a_failed_file_lookup(tmp_path):
    from gesturekit.paths import is_dir, is_file

    long = "0-1:left_hand=high," * 20
    assert len(long) > 255
    assert not is_file(long) and not is_dir(long) and not is_file("a\0b") and not is_dir(tmp_path / ("x" * 300))
    (tmp_path / "f.csv").write_text("start_s,end_s,constraint\n")
    assert is_file(tmp_path / "f.csv") and not is_dir(tmp_path / "f.csv") and is_dir(tmp_path)


@pytest.mark.parametrize(
    "names",
    [("a.wav", "a.mp3"), ("talk one.wav", "talk_one.flac"), ("b.ogg", "b.wav", "c.wav")],
    ids=["same-stem", "same-safe-name", "folder"],
)
def test_synthesize_refuses_speech_files_written_to_the_same_outputs(tmp_path, names):
    from tests.badinput import assert_refused, run_cli, snapshot

    folder = tmp_path / "speech"
    folder.mkdir()
    for name in names:
        (folder / name).write_bytes(b"not read: the names clash first")
    out = tmp_path / "out"
    before = snapshot(folder, out)
    args = [folder] if len(names) == 3 else [folder / n for n in names]
    run = run_cli("synthesize", *args, "--db", tmp_path / "no-db", "--out", out)
    clash = sorted(names)[:2] if len(names) == 3 else names
    assert_refused(run, names=folder / clash[0], problem="would both be written", before=before)
    assert str(folder / clash[1]) in run.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    "command, given, expected",
    [
        ("synthesize", ["--segment", "6", "--record", "4"], (6, 4)),
        ("synthesize", ["--step", "6", "--topk", "4"], (6, 4)),  # the options' earlier names
        ("synthesize", [], (8, 10)),
        ("evaluate", ["--step", "5"], (5, None)),
        ("evaluate", ["--segment", "5"], (5, None)),
    ],
)
def test_segment_and_record_options_read_their_earlier_names_too(command, given, expected):
    from gesturekit.cli._parser import build_parser

    positional = ["speech.wav"] if command == "synthesize" else ["--holdout", "take"]
    args = build_parser().parse_args([command, *positional, *given])
    assert (args.segment, getattr(args, "record", None)) == expected
    assert not hasattr(args, "step") and not hasattr(args, "topk")


def test_every_command_of_the_parser_runs_its_own_function():
    """The options live in _cli_parser.py, the commands in cli.py: each parsed command finds its function."""
    import argparse

    import gesturekit.cli as cli
    from gesturekit.cli._parser import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    names = sorted(sub.choices)
    assert names == sorted(
        ["build-db", "info", "synthesize", "train-refiner", "evaluate", "train-fgd", "stimuli", "study", "app"]
    )
    for name in names:
        assert callable(getattr(cli, "_cmd_" + name.replace("-", "_"))), name
    assert parser.parse_args(["info"]).command == "info"
    # study's subcommands: each its own function in _cli_study.py
    import gesturekit.cli._study as study

    group = next(a for a in sub.choices["study"]._actions if isinstance(a, argparse._SubParsersAction))
    assert {"init", "export-hemvip", "import-hemvip"} <= set(group.choices)
    for name in group.choices:
        assert callable(getattr(study, "_study_" + name.replace("-", "_"))), name
