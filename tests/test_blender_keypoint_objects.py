"""Keypoints from scene objects (blender/scene_trackers.py sample_keypoint_empties, the Keypoints
source's *Scene Objects*): empties named after a layout's points, as FreeMoCap's Blender output
and markerless add-ons leave them, solved like the same points read from a file."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import keying  # noqa: E402
from blender_manikin.core import keypoint_layouts as kl  # noqa: E402

from fixtures_keypoints import hinge_motion, write_layout_npy  # noqa: E402

T = 90


def keyed_empties(points, names, unit=1.0, parent=True):
    """A collection ``keypoints`` of empties named ``names`` keyed at ``points`` ``(T, K, 3)``
    metres / ``unit`` (scene units), on scene frames 1..T, parented to an origin empty moved
    1 m along X (so the world positions are not the keys: the sampler must evaluate)."""
    coll = bpy.data.collections.new("keypoints")
    bpy.context.scene.collection.children.link(coll)
    origin = None
    if parent:
        origin = bpy.data.objects.new("freemocap_origin", None)
        coll.objects.link(origin)
        origin.location = (1.0 / unit, 0.0, 0.0)
    frames = np.arange(1, points.shape[0] + 1, dtype=np.float64)
    for k, name in enumerate(names):
        e = bpy.data.objects.new(name, None)
        coll.objects.link(e)
        e.parent = origin
        act = keying.new_action(f"{name}_action")
        keying.assign_action(e, act)
        keying.key_channels(act, e, frames, [("location", i, "", points[:, k, i] / unit) for i in range(3)])
    return coll


def _solve(s):
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}, s.last_report
    arm = s.armature
    sc = bpy.context.scene
    out = []
    for f in (5, 45, 85):
        sc.frame_set(f)
        W = np.array(arm.matrix_world)
        out.append([(W @ np.append(np.array(pb.head), 1.0))[:3] for pb in arm.pose.bones if pb.name in kl_joints()])
    return np.array(out)


def kl_joints():
    from blender_manikin.core.skeleton import JOINT_NAMES
    return set(JOINT_NAMES)


@pytest.mark.parametrize("unit", [1.0, 0.01])
def test_keypoint_empties_solve_as_the_file_does(addon, tmp_path, unit):
    body, pos, world = hinge_motion(frames=T)
    path = str(tmp_path / "kp.npy")
    clean = write_layout_npy(path, "mediapipe33", body, pos, world)
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    sc.frame_start, sc.frame_end = 1, T
    if unit != 1.0:
        sc.unit_settings.system, sc.unit_settings.scale_length = 'METRIC', unit
    s = sc.manikin
    s.source, s.keypoint_from, s.keypoint_path, s.keypoint_up = 'KEYPOINTS', 'FILE', path, '+Y'
    s.live_rig, s.reuse_armature = False, False
    from_file = _solve(s)
    # names as tools write them: plain, prefixed, Blender's duplicate suffix, other case
    names = [f"Body_{p.title()}" if k % 3 == 1 else (f"{p}.001" if k % 3 == 2 else p)
             for k, p in enumerate(kl.LAYOUTS["mediapipe33"].points)]
    shifted = clean - np.array([1.0, 0.0, 0.0])            # the origin empty puts them back
    coll = keyed_empties(shifted, names, unit)
    s.keypoint_from, s.keypoint_collection = 'OBJECTS', coll
    from_objects = _solve(s)
    assert "keypoints: mediapipe33 (33 points, from the names of 33 scene objects)" in s.last_report
    np.testing.assert_allclose(from_objects, from_file, atol=2e-3 / unit)   # 2 mm


def test_objects_that_are_no_layout_are_refused_with_what_is_missing(addon):
    body, pos, world = hinge_motion(frames=T)
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    names = list(kl.LAYOUTS["coco17"].points)
    names[names.index("left_ankle")] = "left_foot_marker_x"
    coll = keyed_empties(clean, names, parent=False)
    s = bpy.context.scene.manikin
    s.source, s.keypoint_from, s.keypoint_collection = 'KEYPOINTS', 'OBJECTS', coll
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, T
    with pytest.raises(RuntimeError, match="no keypoint layout has all its points among their names "
                                           r"\(closest, coco17, lacks left_ankle\)"):
        bpy.ops.manikin.solve_full_body()


def test_the_panel_shows_the_collection_for_scene_objects(addon):
    from blender_manikin.panels import main as panels
    from blender_util import drawn_props
    s = bpy.context.scene.manikin
    s.source = 'KEYPOINTS'
    drawn = {}
    for frm in ('FILE', 'OBJECTS'):
        s.keypoint_from = frm
        drawn[frm] = drawn_props(panels.MANIKIN_PT_solve, bpy.context)
    assert {"keypoint_from", "keypoint_path", "keypoint_layout"} <= drawn['FILE']
    assert "keypoint_collection" not in drawn['FILE']
    assert "keypoint_collection" in drawn['OBJECTS'] and "keypoint_path" not in drawn['OBJECTS']
    # the feet stand on the soles: the setting is shown here (the Calibration panel is not, for keypoints)
    assert "sole" in drawn['FILE'] and "sole" in drawn['OBJECTS']
    from blender_manikin.blender.properties import config_from_settings
    from blender_manikin.blender.solve_job import SolveError
    with pytest.raises(SolveError, match="choose the collection of the keypoint objects"):
        config_from_settings(bpy.context)
