"""A character's size and rest pose (issue 38): a humanoid is 0.5 to 3 m tall; a file in another evident unit
(centimetres, millimetres, the CMU mocap conversion's units, a glTF converted at 1/100) is read in it and says so;
one no unit makes a humanoid, or whose rest pose has a leg pointing up, is refused naming the file and the bone."""

from __future__ import annotations

import numpy as np
import pytest

from gesturekit.character.retarget import retarget
from gesturekit.character.target import HUMAN_HEIGHT
from gesturekit.character.user import read_character
from gesturekit.errors import ConfigError, GestureKitWarning
from gesturekit.motion import Motion
from tests.character_rigs import RigSpec, cmu_bvh, write_rig


def _height(ch) -> float:
    y = ch.rest_position[:, 1]
    return float(y.max() - y.min())


@pytest.mark.parametrize(
    "unit,note",
    [(0.01, None), (1.0, None), (0.056444, "read in CMU mocap units"), (0.001, "read in millimetres")],
    ids=["cm", "m", "cmu", "mm"],
)
def test_a_bvh_is_read_in_the_unit_that_makes_it_a_humanoid(tmp_path, unit, note):
    path = tmp_path / "skeleton.bvh"
    path.write_bytes(cmu_bvh(unit=unit))
    with pytest.warns(GestureKitWarning) if note else _no_warning():
        ch = read_character(path)
    assert ch.bvh_units == pytest.approx(unit)
    assert _height(ch) == pytest.approx(1.70, abs=1e-6)  # head top (its end site) above the toes
    if note:
        (said,) = ch.notes
        assert note in said and "skeleton.bvh" in said and "1.70 m tall" in said, said
    else:
        assert ch.notes == ()


class _no_warning:
    def __enter__(self):
        import warnings

        self._w = warnings.catch_warnings()
        self._w.__enter__()
        warnings.simplefilter("error", GestureKitWarning)

    def __exit__(self, *exc):
        self._w.__exit__(*exc)


@pytest.mark.parametrize("height,factor", [(0.0175, 100.0), (175.0, 0.01), (1750.0, 0.001)], ids=["1/100", "cm", "mm"])
def test_a_gltf_at_another_scale_is_brought_to_metres_and_exports_back_in_its_own(tmp_path, height, factor):
    """A converter's 1.75 cm rig (as FBX converters write at 1/100) is read 1.75 m tall, and our motion on it
    is written back into its file at its own scale (the read-back error is measured in metres)."""
    from gesturekit.demo import open_default_database
    from gesturekit.export.character import export_character_glb

    path = write_rig(tmp_path, RigSpec(height=height, rest="A", roll_seed=1), "tiny")
    with pytest.warns(GestureKitWarning, match="tiny.glb"):
        ch = read_character(path)
    assert ch.bvh_units == factor
    assert HUMAN_HEIGHT[0] <= _height(ch) <= HUMAN_HEIGHT[1]
    assert _height(ch) == pytest.approx(height * factor, rel=0.05)
    db = open_default_database()
    motion = Motion(db.poses[:1].reshape(-1, 55, 3).astype(np.float32), 15.0, db.joint_presence)
    out = retarget(motion, ch)
    assert out.report.reach_scale[0] == pytest.approx(out.report.reach_scale[1]) and 0.7 < out.scale < 1.4
    written = export_character_glb(tmp_path / "out.glb", out)
    assert written.max_error < 1e-4  # metres, read back from the file in its own units


def test_a_character_no_unit_makes_a_humanoid_is_refused(tmp_path):
    path = tmp_path / "tower.bvh"
    path.write_bytes(cmu_bvh(unit=1e-6))  # 1 700 000 units: 17 km in centimetres, 1.7 km in millimetres
    with pytest.raises(ConfigError, match="no unit .* makes it a humanoid of 0.5 to 3.0 m") as e:
        read_character(path)
    assert "tower.bvh" in str(e.value)


def test_a_rest_pose_with_a_leg_pointing_up_is_refused_naming_the_leg(tmp_path):
    path = tmp_path / "upside.bvh"
    path.write_bytes(cmu_bvh(leg_up=True))
    with pytest.raises(ConfigError, match="leg from 'LHipJoint' ends at 'LeftToeBase_End', 0.9. m above") as e:
        read_character(path)
    assert "upside.bvh" in str(e.value)
    path.write_bytes(cmu_bvh())  # the same skeleton standing is read
    assert read_character(path).n_bones > 30
