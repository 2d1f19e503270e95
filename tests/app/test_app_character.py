"""The user's character in the app, run headless with Streamlit's AppTest: upload, what matched, errors, views,
downloads."""

from __future__ import annotations

import json

import pytest
from streamlit.testing.v1 import AppTest

from gesturekit.app import HOME
from gesturekit.character.glb import read_glb
from gesturekit.character.user import read_character_upload
from gesturekit.skeleton import JOINT_NAMES
from tests.app.test_app_synthesize import speech_file
from tests.character_rigs import CASES, RigSpec, custom_map, rig_files, truth
from tests.conftest import shown, viewer
from tests.waits import APP_RUN_S

pytestmark = pytest.mark.slow  # each module builds its demo database (demo_home) and runs pages in AppTest

SYNTH, INSPECT = "views/1_Synthesize.py", "views/2_Retrieval_inspector.py"
TIMEOUT = APP_RUN_S  # a script run's deadline, which ends a hang (tests/waits.py)
FILE, MAP = "_gk.character_file.0", "_gk.character_map.0"


def rig(case: str) -> tuple[str, bytes]:
    ((name, data),) = rig_files(CASES[case]).items()
    return name, data


def open_page() -> AppTest:
    at = AppTest.from_file(str(HOME), default_timeout=TIMEOUT).run()
    at.switch_page(SYNTH).run()
    assert not at.exception, at.exception
    return at


def upload_character(at: AppTest, name: str, data: bytes, key: str = FILE) -> AppTest:
    at.file_uploader(key=key).set_value((name, data, "application/octet-stream")).run()
    assert not at.exception, at.exception
    return at


def errors(at: AppTest) -> list[str]:
    return [shown(e.value) for e in at.error]


def captions(at: AppTest) -> list[str]:
    return [shown(c.value) for c in at.caption]


def run_synthesis(at: AppTest) -> AppTest:
    at.file_uploader(key="synth.upload").set_value(("speech.wav", speech_file(3.0), "audio/wav")).run()
    if at.toggle(key="_w.synth.refine").value:
        at.toggle(key="_w.synth.refine").set_value(False).run()
    at.button(key="synth.go").click().run()
    assert not at.exception and not errors(at), (at.exception, errors(at))
    return at


def test_a_character_is_matched_drawn_and_written_until_the_default_is_chosen(app_env):
    name, data = rig("vrm0_a")
    at = upload_character(open_page(), "my avatar.vrm", data)
    assert not errors(at)
    assert any("my avatar.vrm is shown" in shown(s.value) for s in at.success)
    mine = read_character_upload(name, data)
    said = " ".join(captions(at))
    assert "matched by VRM 0.x humanoid" in said and f"{mine.n_bones} bones" in said
    at = run_synthesis(at)
    res = at.session_state["gk.synthesis"]["result"]
    skel = viewer(at, "synth.skeleton")
    m = skel["motions"][0]
    # their bones and mesh, not our 55 joints
    assert m["rig"]["names"] == list(mine.names) and m["scheme"] == "character"
    assert len(skel["times"]) == res.n_frames
    # one line per view, named as the view is ("k-NN, dead-blended joins: 42 bones follow ours within ...")
    assert any(c.startswith("k-NN") and ": " in c and "bones follow ours within" in c for c in captions(at))
    downloads = {d.proto.label: d for d in at.get("download_button")}
    assert {"Character GLB", "Its speech (WAV)", "Character BVH"} <= set(downloads)
    made = at.session_state["_gk.character_files"]
    glb = next(v for k, v in made.items() if k[2] == "glb")
    doc, _ = read_glb(glb["data"])
    assert [a["name"] for a in doc["animations"]][-1] == "gesturekit"
    assert "VRM" in doc.get("extensions", {})  # a VRM stays a VRM
    bvh = next(v for k, v in made.items() if k[2] == "bvh")
    assert bvh["data"].startswith(b"HIERARCHY") and f"MOTION\nFrames: {res.n_frames}" in bvh["data"].decode()

    # the MP4 is rendered on it, and again on another character
    at.button(key="synth.render").click().run()
    assert not at.exception and not errors(at), (at.exception, errors(at))
    made_video = at.session_state["_synth.video"]
    kept = at.session_state["gk.character"]
    assert made_video["character"] == (*kept["token"], kept["character"].wrist_slack)  # the file, map and slack
    assert made_video["bytes"][4:8] == b"ftyp"
    assert any(d.proto.label == "Video (MP4)" for d in at.get("download_button"))

    # the inspector's 3D view draws it too, the candidate looked at
    at.number_input(key="_w.synth.record").set_value(3).run()
    at.button(key="synth.go").click().run()
    at.switch_page(INSPECT).run()
    assert not at.exception and not errors(at), (at.exception, errors(at))
    views = viewer(at, "inspect.views")
    assert len(views["motions"]) == 1
    assert all(m["rig"]["names"] == list(mine.names) for m in views["motions"])
    assert sum("bones follow ours within" in c for c in captions(at)) >= len(views["motions"])
    at.switch_page(SYNTH).run()

    at.button(key="_gk.character_default").click().run()
    assert not at.exception and "gk.character" not in at.session_state
    m = viewer(at, "synth.skeleton")["motions"][0]
    assert m["rig"]["names"] == list(JOINT_NAMES)
    assert "_synth.video" not in at.session_state  # the video of their character is not offered for ours
    assert "Character GLB" not in {d.proto.label for d in at.get("download_button")}


def test_a_broken_character_file_is_an_error_message_not_a_traceback(app_env):
    at = upload_character(open_page(), "broken.glb", b"these are my notes, not a character" * 30)
    said = errors(at)
    assert len(said) == 1 and said[0].startswith("broken.glb: ") and "glTF" in said[0]
    assert "gk.character" not in at.session_state
    assert any("The default body is shown." in c for c in captions(at))
    at.run()  # the same upload is not read again, and still reported
    assert errors(at) == said and not at.exception


def test_a_rig_missing_a_bone_is_named(app_env):
    name, data = rig("missing_elbow")
    at = upload_character(open_page(), name, data)
    said = errors(at)
    assert len(said) == 1 and "left_elbow" in said[0] and "bone map" in said[0]
    assert "gk.character" not in at.session_state
    # the bones it has, as a tree with their rest positions, to write the map from
    (tree,) = [c.value for c in at.code]
    assert tree.splitlines()[0].startswith("mixamorig:Hips (0.00, 0.98, 0.00)")
    assert "  mixamorig:Spine (" in tree and f"{truth(CASES['missing_elbow']).bone_names[-1]} (" in tree
    assert any("rest positions" in c for c in captions(at))


def test_a_bvh_character_and_a_bone_map(app_env):
    name, data = rig("bvh_zeggs_a")
    at = upload_character(open_page(), name, data)
    assert not errors(at)
    said = " ".join(captions(at))
    assert "matched by zeggs names" in said and "capsules around its bones" in said
    # custom names on a tree whose arms differ (one without its collar) need the user's map: without it the file is
    # refused, with it the character is read
    spec = RigSpec(naming="custom", roll_seed=5, drop=("left_collar",))
    ((name, data),) = rig_files(spec).items()
    at = upload_character(at, name, data)
    assert errors(at) and at.session_state["gk.character"]["name"] == "zeggs.bvh"  # the last good one stays
    bone_map = json.dumps(custom_map(spec)).encode()
    at = upload_character(at, "bones.json", bone_map, key=MAP)
    assert not errors(at) and at.session_state["gk.character"]["name"] == name
    assert "matched by JSON map bones.json" in " ".join(captions(at))
    ch = at.session_state["gk.character"]["character"]
    assert ch.matched() == truth(spec).joint_map


def test_the_wrist_slack_slider_poses_the_arms_again(app_env):
    ((name, data),) = rig_files(RigSpec(arm=0.9, forearm=1.1)).items()  # an upper arm shorter than ours
    at = run_synthesis(upload_character(open_page(), name, data))

    def wrists() -> list[float]:
        said = [c for c in captions(at) if c.startswith("k-NN") and "wrists within " in c]
        return [float(c.split("wrists within ")[1].split(" %")[0]) for c in said]

    slider = at.slider(key="_gk.wrist_slack")
    assert slider.value == 5.0 and slider.max == 20.0
    before = at.session_state["gk.character"]["character"]
    assert before.wrist_slack == 0.05 and wrists() and all(0.0 < w <= 5.0 for w in wrists())
    token = at.session_state["_gk.character_files"] and next(iter(at.session_state["_gk.character_files"]))[1]
    at.slider(key="_gk.wrist_slack").set_value(0.0).run()
    assert not at.exception and not errors(at), (at.exception, errors(at))
    assert at.session_state["gk.character"]["character"].wrist_slack == 0.0
    assert wrists() and all(w == 0.0 for w in wrists())  # the hands exactly where ours reach
    made = at.session_state["_gk.character_files"]
    assert any(key[1] != token and key[1][-1] == 0.0 for key in made)  # its files are made again for it


def test_a_file_no_reader_foresaw_is_a_message_with_a_reference(app_env, monkeypatch):
    import sys

    at = open_page()

    def unforeseen(name, data, *, bone_map=None):
        raise IndexError("deep inside a reader")

    monkeypatch.setattr(sys.modules["gesturekit.app.characters"], "read_character_upload", unforeseen)
    name, data = rig("mixamo_t")
    at = upload_character(at, "odd.glb", data)
    (said,) = errors(at)
    assert said.startswith("odd.glb: could not be read as a character") and "reference" in said
    assert "deep inside" not in said and "Traceback" not in said
    assert "gk.character" not in at.session_state
    at.file_uploader(key="synth.upload")  # the page is drawn on below the sidebar


def test_the_characters_own_clips_are_kept_after_ours_or_left_out(app_env, tmp_path):
    from tests.export.test_export_character import waving_glb

    at = upload_character(open_page(), "waving.glb", waving_glb(tmp_path).read_bytes())
    assert at.radio(key="_gk.character_clips").value == "keep"  # the default: theirs kept, ours first
    at = run_synthesis(at)

    def clips() -> list[str]:
        made = at.session_state["_gk.character_files"]
        (glb,) = [v for k, v in made.items() if k[2] == "glb" and k[3] == at.radio(key="_gk.character_clips").value]
        return [a["name"] for a in read_glb(glb["data"])[0]["animations"]]

    assert clips() == ["gesturekit", "wave"]
    at.radio(key="_gk.character_clips").set_value("drop").run()
    assert not at.exception and not errors(at), (at.exception, errors(at))
    assert clips() == ["gesturekit"]
    assert any("its own clips left out: wave" in c for c in captions(at))
