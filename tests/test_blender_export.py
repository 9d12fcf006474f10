"""JSON and BVH output: schema validation, content, and a BVH round trip through Blender's importer."""
import copy
import json

import numpy as np
import pytest

from blender_manikin.core import export_bvh, export_json
from blender_manikin.core import rotations as rot
from blender_manikin.core import skeleton as sk

from blender_util import synthetic_result


def test_json_document_valid_and_consistent(tmp_path):
    res = synthetic_result(T=20, fps=30.0)
    path = export_json.write_json(tmp_path / "take.json", res, source="take.csv")
    doc = json.loads(path.read_text())
    assert export_json.validate_document(doc) == []
    assert doc["fps"] == 30.0 and doc["t0"] == 12.5 and doc["source"] == "take.csv"
    assert doc["joints"] == list(sk.JOINT_NAMES) and doc["parents"] == sk.PARENTS.tolist()
    pos = np.asarray(doc["positions"])
    q = np.asarray(doc["rotations"])
    assert pos.shape == (20, 22, 3) and q.shape == (20, 22, 4)
    np.testing.assert_allclose(pos, res.positions, atol=1e-6)
    np.testing.assert_allclose(rot.quat_to_matrix(q), res.world_rot, atol=1e-5)
    assert np.all(np.sum(q[1:] * q[:-1], -1) > 0)
    for i, k in enumerate(("left_arm", "right_arm", "left_leg", "right_leg")):
        d = np.asarray(doc["swivel"][k]) - res.swivel[:, i]
        assert np.max(np.abs(np.angle(np.exp(1j * d)))) < 1e-5
    assert set(doc["trackers"]) == {"head", "left_hand", "right_hand"}
    np.testing.assert_allclose(doc["trackers"]["left_hand"], res.targets.pos["left_hand"], atol=1e-6)
    # frame k of the output is at t0 + k / fps
    assert doc["num_frames"] == 20


@pytest.mark.parametrize("mutate, fragment", [
    (lambda d: d.pop("fps"), "missing required 'fps'"),
    (lambda d: d.__setitem__("fps", 0), "exclusiveMinimum"),
    (lambda d: d["positions"][3].pop(), "minItems"),
    (lambda d: d["rotations"][0][0].__setitem__(0, "x"), "expected number"),
    (lambda d: d["swivel"].pop("left_leg"), "left_leg"),
    (lambda d: d["trackers"].__setitem__("left_knee", []), "left_knee"),
    (lambda d: d["trackers"]["head"].pop(), "frames"),
    (lambda d: d.__setitem__("joints", d["joints"][::-1]), "must equal"),
    (lambda d: d.__setitem__("extra", 1), "unexpected key"),
    (lambda d: d["rotations"][2].__setitem__(5, [2.0, 0, 0, 0]), "unit quaternion"),
])
def test_validator_rejects(mutate, fragment):
    doc = export_json.result_to_dict(synthetic_result(T=6, fps=30.0), source="x")
    assert export_json.validate_document(doc) == []
    bad = copy.deepcopy(doc)
    mutate(bad)
    errors = export_json.validate_document(bad)
    assert errors and any(fragment in e for e in errors), errors


def test_json_nan_trackers_become_null(tmp_path):
    res = synthetic_result(T=5, fps=30.0)
    res.targets.pos["head"][2] = np.nan
    doc = json.loads(export_json.write_json(tmp_path / "a.json", res).read_text())
    assert doc["trackers"]["head"][2] == [None, None, None]
    assert export_json.validate_document(doc) == []


def test_schema_is_json():
    assert json.loads(json.dumps(export_json.JSON_SCHEMA))["properties"]["fps"]["type"] == "number"


def test_euler_zxy_roundtrip():
    """The BVH exporter's channel order, through the one Euler implementation."""
    rng = np.random.default_rng(1)
    R = rot.axis_angle_to_matrix(rng.normal(size=(200, 3)) * 1.5)
    e = rot.matrix_to_euler(R, "ZXY")
    np.testing.assert_allclose(rot.euler_to_matrix(e, "ZXY"), R, atol=1e-9)
    z, x, y = e[..., 0], e[..., 1], e[..., 2]
    Rz = rot.axis_angle_rotation(np.array([0, 0, 1.0]), z)
    Rx = rot.axis_angle_rotation(np.array([1.0, 0, 0]), x)
    Ry = rot.axis_angle_rotation(np.array([0, 1.0, 0]), y)
    np.testing.assert_allclose(Rz @ Rx @ Ry, R, atol=1e-9)


@pytest.mark.parametrize("units", ["cm", "m"])
def test_bvh_roundtrip_through_blender(tmp_path, units):
    bpy = pytest.importorskip("bpy")
    from blender_util import fresh_scene
    fresh_scene()
    T = 10
    res = synthetic_result(T=T, fps=24.0)
    path = export_bvh.write_bvh(tmp_path / "take.bvh", res, units=units)
    text = path.read_text()
    assert text.startswith("HIERARCHY\nROOT pelvis") and f"Frames: {T}" in text
    scale = 0.01 if units == "cm" else 1.0
    bpy.ops.import_anim.bvh(filepath=str(path), global_scale=scale, frame_start=1,
                            use_fps_scale=False, rotate_mode='NATIVE', axis_forward='-Z', axis_up='Y')
    obj = bpy.context.view_layer.objects.active
    assert obj.type == 'ARMATURE'
    pos = res.positions
    err = 0.0
    for k in range(T):
        bpy.context.scene.frame_set(1 + k)
        mw = np.array(obj.matrix_world)
        for j, name in enumerate(sk.JOINT_NAMES):
            h = mw @ np.append(np.array(obj.pose.bones[name].head), 1.0)
            err = max(err, np.max(np.abs(h[:3] - pos[k, j])))
    assert err < 1e-4
