"""The mannequin mesh on a solved armature (blender/body_mesh.py): made by a solve, skinned to the
bones so it follows the live rig and plain keys as numpy poses it, made once per armature, gone
with a failed solve or an undo, copied by Bake to FK, and left out when asked."""
import os

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import blender_manikin  # noqa: E402
from blender_manikin.blender import body_mesh, live_rig, solve_job  # noqa: E402
from blender_manikin.core import mannequin as mq  # noqa: E402
from blender_manikin.core.skeleton import JOINT_NAMES  # noqa: E402

from blender_util import fresh_scene  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def _solve(**kw):
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    job = solve_job.SolveJob(solve_job.SolveConfig(source="FILE", filepath=EXAMPLE, fps=30.0, **kw))
    return job, job.run(bpy.context)


def _evaluated(obj, frame):
    """World positions ``(V, 3)`` of ``obj``'s evaluated mesh at scene ``frame``."""
    bpy.context.scene.frame_set(int(frame))
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    me = ev.to_mesh()
    try:
        co = np.empty(3 * len(me.vertices))
        me.vertices.foreach_get("co", co)
    finally:
        ev.to_mesh_clear()
    W = np.array(obj.matrix_world)
    return co.reshape(-1, 3) @ W[:3, :3].T + W[:3, 3]


@pytest.mark.parametrize("live", [True, False])
def test_a_solve_gives_a_mannequin_that_follows_the_rig(live):
    fresh_scene()
    job, out = _solve(live_rig=live)
    arm, res = out.armature, job.result
    mo = body_mesh.find_body_mesh(arm)
    assert mo is not None and out.body_mesh == mo
    assert mo.parent == arm and mo.users_collection == arm.users_collection
    mods = [m for m in mo.modifiers if m.type == 'ARMATURE']
    assert len(mods) == 1 and mods[0].object == arm
    m = mq.mannequin_mesh(res.body)
    assert len(mo.data.vertices) == len(m.verts)
    # every vertex in exactly one group, the bone's, weight 1
    groups = {g.index: g.name for g in mo.vertex_groups}
    assert set(groups.values()) == set(m.bone_names)
    for v in list(mo.data.vertices)[::97]:
        assert [(groups[g.group], g.weight) for g in v.groups] == [(JOINT_NAMES[m.bone[v.index]], 1.0)]
    assert mo.data.materials[0].name == body_mesh.MATERIAL
    # the evaluated mesh is the numpy posing of the solved frames (the live rig evaluates the
    # same pose within a fraction of a millimetre)
    pos, world = res.fk()
    posed = mq.posed_vertices(m, world, pos, res.body)
    for k in (0, 55, len(out.frames) - 1):
        err = np.abs(_evaluated(mo, out.frames[k]) - posed[k]).max()
        assert err < 1e-3, (k, err)


def test_one_mannequin_per_armature_and_none_when_off():
    fresh_scene()
    _, out = _solve()
    n_meshes = len(bpy.data.meshes)
    _, again = _solve(reuse_armature=out.armature)          # the same body: the armature reused
    assert again.armature == out.armature and again.body_mesh is None
    assert len(bpy.data.meshes) == n_meshes
    assert len([c for c in out.armature.children if c.type == 'MESH']) == 1
    # a user's own mesh on the armature is not taken for the mannequin, nor changed
    own = bpy.data.objects.new("Suit", bpy.data.meshes.new("Suit"))
    bpy.context.scene.collection.objects.link(own)
    own.parent = out.armature
    assert body_mesh.find_body_mesh(out.armature).name.endswith("_mannequin")
    _, off = _solve(body_mesh=False)                        # a new armature, no mannequin
    assert off.armature != out.armature and body_mesh.find_body_mesh(off.armature) is None
    assert off.body_mesh is None and len(bpy.data.meshes) == n_meshes + 1


def test_a_failed_solve_leaves_no_mannequin(monkeypatch):
    fresh_scene()
    before = (len(bpy.data.objects), len(bpy.data.meshes))

    def broken(*a, **k):
        raise RuntimeError("live rig failed")

    monkeypatch.setattr(live_rig, "build_live_rig", broken)
    with pytest.raises(RuntimeError, match="live rig failed"):
        _solve()
    assert (len(bpy.data.objects), len(bpy.data.meshes)) == before


@pytest.fixture
def panel_settings():
    """The add-on registered on an empty 30 fps scene, its panel set to solve the example;
    yields the settings."""
    fresh_scene()
    blender_manikin.register()
    try:
        sc = bpy.context.scene
        sc.render.fps = 30
        s = sc.manikin
        s.source, s.filepath = 'FILE', EXAMPLE
        yield s
    finally:
        blender_manikin.unregister()


def test_undo_of_the_solve_operator_removes_the_mannequin(panel_settings):
    s = panel_settings
    assert s.body_mesh                                   # on by default
    bpy.ops.ed.undo_push(message="before solve")
    assert bpy.ops.manikin.solve_full_body('EXEC_DEFAULT', True) == {'FINISHED'}
    assert body_mesh.find_body_mesh(s.armature) is not None
    bpy.ops.ed.undo()
    assert not [o for o in bpy.data.objects if o.get(body_mesh.PROP_MESH)]
    bpy.ops.ed.redo()
    assert len([o for o in bpy.data.objects if o.get(body_mesh.PROP_MESH)]) == 1


def test_bake_to_fk_copies_the_mannequin_onto_the_baked_armature():
    fresh_scene()
    _, out = _solve(live_rig=True)
    arm = out.armature
    f0, f1 = int(out.frames[0]), int(out.frames[-1])
    baked = live_rig.bake_live_rig(arm, f0, f1)
    mo, mb = body_mesh.find_body_mesh(arm), body_mesh.find_body_mesh(baked)
    assert mb is not None and mb != mo and mb.parent == baked
    assert [m.object for m in mb.modifiers if m.type == 'ARMATURE'] == [baked]
    assert [m.object for m in mo.modifiers if m.type == 'ARMATURE'] == [arm]      # untouched
    for f in (f0 + 10, (f0 + f1) // 2):
        assert np.abs(_evaluated(mb, f) - _evaluated(mo, f)).max() < 1e-3


def test_the_panel_setting_reaches_the_solve(panel_settings):
    """Frames and Output shows *Mannequin*; off, the operator's solve makes none."""
    from types import SimpleNamespace
    from blender_manikin.panels import main as panels
    from blender_util import PanelLayout
    s = panel_settings
    log = []
    panels.MANIKIN_PT_output.draw(SimpleNamespace(layout=PanelLayout(log)), bpy.context)
    assert ("prop", "body_mesh") in log
    s.body_mesh, s.reuse_armature = False, False
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert body_mesh.find_body_mesh(s.armature) is None
    s.body_mesh = True
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert body_mesh.find_body_mesh(s.armature) is not None


def test_a_mannequin_that_cannot_be_built_does_not_cost_the_solve(monkeypatch):
    """The mannequin is a viewing aid: a body it cannot be built for leaves the solve written
    without it, and the summary says why."""
    from blender_manikin.core import mannequin

    def cannot(body, *a, **k):
        raise ValueError("the body's rest pose gives no finite mannequin (a zero-length bone?)")

    monkeypatch.setattr(body_mesh, "mannequin_mesh", cannot)
    assert mannequin.mannequin_mesh is not cannot
    fresh_scene()
    job, out = _solve()
    assert out.armature is not None and out.body_mesh is None and body_mesh.find_body_mesh(out.armature) is None
    assert "no mannequin: the body's rest pose gives no finite mannequin" in job.summary()
