"""Study stimuli on the user's character: every MP4 shows it, the study records its file, errors are one line."""

from __future__ import annotations

import hashlib
import json

import imageio_ffmpeg
import numpy as np
import pandas as pd
import pytest

from gesturekit.character.user import read_character
from gesturekit.cli import main
from gesturekit.demo import open_default_database
from gesturekit.errors import ConfigError, InputFileError
from gesturekit.evaluate.run import held_out
from gesturekit.study.stimuli import make_stimuli, stimulus_style
from gesturekit.viz.character_render import CharacterStage
from tests.character_rigs import CASES, custom_map, write_rig
from tests.viz.test_video_character import drawn, iou, stage_alone
from tests.viz.test_video_character_user import reference_vertices, silhouette

HOLDOUT = "demo0_000:10-11.2"
SIZE = (160, 120)


def frames_of(path) -> list[np.ndarray]:
    reader = imageio_ffmpeg.read_frames(str(path))
    next(reader)
    return [np.frombuffer(f, np.uint8).reshape(SIZE[1], SIZE[0], 3).astype(int) for f in reader]


def hue(image: np.ndarray) -> np.ndarray:
    """Pixels with a colour (not a grey)."""
    return image.max(axis=-1) - image.min(axis=-1) > 30


@pytest.mark.slow
def test_stimuli_command_renders_every_stimulus_on_the_character_and_records_its_file(tmp_path, capsys):
    rig = write_rig(tmp_path, CASES["vrm1_t"], name="presenter")  # a textured VRM 1.0
    out = tmp_path / "study"
    args = ["stimuli", "--holdout", HOLDOUT, "--systems", "gt,knn", "--out", str(out), "--resolution", "160x120"]
    assert main([*args, "--workers", "1", "--seed", "4", "--character", str(rig)]) == 0
    assert "2 stimuli" in capsys.readouterr().out
    study = json.loads((out / "study.json").read_text())
    record = study["character"]
    assert record == {
        "file": "presenter.vrm",
        "sha256": hashlib.sha256(rig.read_bytes()).hexdigest(),
        "matched_by": "VRM 1.0 humanoid",
        "wrist_slack": 0.05,
    }
    manifest = pd.read_csv(out / "manifest.csv")
    assert list(manifest.columns) == ["id", "file", "audio", "system", "controls", "seed", "duration_s"]
    for f in manifest["file"]:  # the videos do not name the character's file
        data = (out / f).read_bytes()
        assert b"presenter" not in data
    # the recorded motion's stimulus is the retargeted skin seen through the study's one fixed camera
    ch = read_character(rig)
    gt = held_out(open_default_database(), HOLDOUT).motion
    stage = CharacterStage([gt], view_box=study["view_box"], character=ch)
    video = frames_of(out / manifest.loc[manifest["system"] == "gt", "file"].item())
    assert len(video) == gt.n_frames
    # the stage the stimuli stand on, without the character: as make_stimuli frames them
    alone = stage_alone([gt], (160, 120), style=stimulus_style(study["view_box"]), character=ch)
    for frame in (0, 11):
        expected = silhouette(reference_vertices(ch, ch.skin, gt, frame), ch.skin.faces, stage.camera(4 / 3))
        assert expected.sum() > 300
        assert iou(drawn(video[frame].astype(np.uint8), alone, tolerance=40), expected) >= 0.88
    # both stimuli show the character in its own colours, framed alike
    other = frames_of(out / manifest.loc[manifest["system"] == "knn", "file"].item())
    for image in (video[5], other[5]):
        assert hue(image).sum() > 100
    np.testing.assert_allclose(
        np.asarray(study["view_box"]) + ch.rest_position[ch.pelvis][:, None], stage.box.T, atol=1e-12
    )


def test_a_bvh_skeleton_in_stimuli_is_drawn_in_the_neutral_grey(tmp_path):
    rig = write_rig(tmp_path, CASES["bvh_zeggs_a"], name="skeleton")
    res = make_stimuli(
        open_default_database(),
        out=tmp_path / "study",
        holdouts=[HOLDOUT],
        systems="gt",
        resolution=SIZE,
        workers=1,
        character=read_character(rig),
    )
    assert res.settings["character"]["sha256"] == hashlib.sha256(rig.read_bytes()).hexdigest()
    assert res.settings["character"]["file"] == "skeleton.bvh"
    image = frames_of(res.videos[0])[3]
    gt = held_out(open_default_database(), HOLDOUT).motion
    alone = stage_alone([gt], SIZE, style=stimulus_style(res.settings.get("view_box")), character=read_character(rig))
    body = drawn(image.astype(np.uint8), alone, tolerance=40)
    assert body.sum() > 200
    assert hue(image).sum() == 0  # tubes in the neutral scheme: no colour tells anything apart


def test_a_bone_map_is_recorded_with_its_file(tmp_path):
    spec = CASES["custom_names"]
    rig = write_rig(tmp_path, spec, name="custom")
    bone_map = tmp_path / "map.json"
    bone_map.write_text(json.dumps(custom_map(spec)))
    res = make_stimuli(
        open_default_database(),
        out=tmp_path / "study",
        holdouts=[HOLDOUT],
        systems="gt",
        resolution=(64, 48),
        workers=1,
        character=rig,
        character_map=bone_map,
        wrist_slack=0.0,
    )
    assert res.settings["character"]["bone_map"] == {
        "file": "map.json",
        "sha256": hashlib.sha256(bone_map.read_bytes()).hexdigest(),
    }
    assert res.settings["character"]["matched_by"] == "JSON map map.json"
    assert res.settings["character"]["wrist_slack"] == 0.0  # the hands held exactly where ours reach


def test_bad_characters_are_one_line_errors_and_no_study_is_started(tmp_path, capsys):
    bad = tmp_path / "broken.vrm"
    bad.write_bytes(b"glTF not really")
    rig = write_rig(tmp_path, CASES["mixamo_t"], name="fine")
    wrong_map = tmp_path / "wrong.json"
    wrong_map.write_text(json.dumps({"pelvis": "NoSuchBone", "joints": {}}))
    base = ["stimuli", "--holdout", HOLDOUT, "--systems", "gt", "--resolution", "64x48", "--workers", "1"]
    cases = [
        (["--character", str(bad)], "broken.vrm"),
        (["--character", str(tmp_path / "missing.glb")], "no such character file"),
        (["--character", str(tmp_path / "model.obj")], "not .obj"),
        (["--character", str(rig), "--character-map", str(wrong_map)], "NoSuchBone"),
        (["--character-map", str(wrong_map)], "needs a character"),
        (["--wrist-slack", "0.1"], "says how a character's arms are posed"),
        (["--character", str(rig), "--wrist-slack", "0.3"], "--wrist-slack must be a number from 0 to 0.2"),
    ]
    for k, (extra, words) in enumerate(cases):
        out = tmp_path / f"study{k}"
        assert main([*base, "--out", str(out), *extra]) == 2
        err = capsys.readouterr().err
        assert err.startswith("gesturekit: error:") and words in err
        assert "Traceback" not in err and len(err.strip().splitlines()) == 1
        assert not out.exists()
    db = open_default_database()
    with pytest.raises(InputFileError):
        make_stimuli(db, out=tmp_path / "x", holdouts=[HOLDOUT], systems="gt", character=bad)
    with pytest.raises(ConfigError, match="already matched"):
        make_stimuli(
            db, out=tmp_path / "y", holdouts=[HOLDOUT], systems="gt", character=read_character(rig), character_map={}
        )
