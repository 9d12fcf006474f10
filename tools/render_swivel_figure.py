#!/usr/bin/env python3
"""Render the README figure of the live swivel rig: one pose, two swivel values, side by side.

    python tools/render_swivel_figure.py --out docs/swivel.png          # bpy module
    blender -b --python tools/render_swivel_figure.py -- --out docs/swivel.png

Builds one solved frame (hands in front of the chest, left knee raised) with
``writer.write_result`` twice, converts both armatures with
``live_rig.build_live_rig`` and, on the right-hand copy, edits the keyed
swivel angles (elbows +/-70 degrees, left knee -50 degrees) exactly as an
animator would in the Graph Editor.  Hands and feet stay where they are; the
elbows / knees swing around the shoulder-wrist / hip-ankle axes (drawn as
thin lines, with the swivel circles).  The bones are made visible by a
skinned stick mesh (an Armature modifier, so the render shows the evaluated
rig); captions are text objects.  Workbench engine, orthographic camera;
the PNG is small (RGB, < 300 KB at the default 960x600).
"""
from __future__ import annotations

import argparse
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

import bpy  # noqa: E402

from blender_manikin.blender import live_rig, writer  # noqa: E402
from blender_manikin.core import limb_solver as ls  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402
from blender_manikin.core.pose_result import PoseResult  # noqa: E402

#: swivel change shown on the right (radians), per limb in LIMB_NAMES order
DELTA = np.radians([70.0, -70.0, -50.0, 0.0])
GAP = 1.25          # metres between the two figures (world X)


def _args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=os.path.join(ROOT, "docs", "swivel.png"), help="PNG to write")
    p.add_argument("--width", type=int, default=960)
    p.add_argument("--height", type=int, default=600)
    return p.parse_args(argv)


def figure_pose():
    """One-frame PoseResult: upright torso, hands in front of the chest, left knee raised."""
    body = sk.make_body(1.75)
    local = np.broadcast_to(np.eye(3), (1, sk.NUM_JOINTS, 3, 3)).copy()
    root = body.root_rest[None].copy()
    pos, wrot = sk.forward_kinematics(local, root, body)
    ends = np.array([[0.20, -0.38, 1.12], [-0.24, -0.34, 1.28],     # wrists
                     [0.09, -0.28, 0.42], [-0.09, -0.02, 0.07]])    # ankles
    swivel = np.array([[0.25, -0.25, 0.0, 0.0]])
    sol = ls.solve_limbs(pos[:, ls.LIMB_BASE], ends[None], swivel, body.limb_lengths(),
                         wrot[:, ls.LIMB_PARENT])
    local[:, ls.LIMB_BASE] = sol.base_local
    local[:, ls.LIMB_MID] = sol.mid_local
    for li, j in enumerate(ls.LIMB_END):          # hands / feet keep their rest orientation in the world
        local[:, j] = np.swapaxes(sol.mid_world[:, li], -1, -2)
    return PoseResult(fps=24.0, body=body, local_rot=local, root_pos=root, swivel=swivel,
                      contacts=np.zeros((1, 2), bool))


def _material(name, rgb):
    m = bpy.data.materials.new(name)
    m.diffuse_color = (*rgb, 1.0)
    return m


def stick_mesh(arm_obj, mats, bones=None):
    """A skinned capsule-ish stick figure of the deform bones (cylinders + joint spheres); bones:
    the names to draw (default: every deforming bone but the live rig's)."""
    import bmesh
    from mathutils import Matrix, Vector

    bm = bmesh.new()
    deform = bm.verts.layers.deform.verify()
    names = []           # vertex group index -> bone name
    limb_bones = {n for r in live_rig.LIMB_RIGS for n in (r.base, r.mid)}
    for b in arm_obj.data.bones:
        if not b.use_deform or b.name in live_rig.RIG_BONES or (bones is not None and b.name not in bones):
            continue
        head, tail = Vector(b.head_local), Vector(b.tail_local)
        length = (tail - head).length
        radius = 0.045 if b.name == "head" else 0.022 if b.name in limb_bones else 0.028
        rot = (tail - head).normalized().to_track_quat('Z', 'Y').to_matrix().to_4x4()
        verts = bmesh.ops.create_cone(bm, cap_ends=True, segments=12, radius1=radius,
                                      radius2=radius * 0.8, depth=length * 0.9,
                                      matrix=Matrix.Translation((head + tail) / 2) @ rot)["verts"]
        verts += bmesh.ops.create_uvsphere(bm, u_segments=12, v_segments=8, radius=radius * 1.25,
                                           matrix=Matrix.Translation(head))["verts"]
        parent = b.parent
        if bones is not None and parent is not None and parent.name not in bones:
            parent = None                # a mechanism bone between drawn ones: no bridge
        if parent is not None and not b.use_connect and (head - parent.head_local).length > 1e-3:
            # bridge the gap to an unconnected child (pelvis -> hips, spine3 -> collars)
            a = Vector(parent.head_local)
            rot2 = (head - a).normalized().to_track_quat('Z', 'Y').to_matrix().to_4x4()
            bridge = bmesh.ops.create_cone(bm, cap_ends=True, segments=12, radius1=0.02, radius2=0.02,
                                           depth=(head - a).length,
                                           matrix=Matrix.Translation((head + a) / 2) @ rot2)["verts"]
            if parent.name not in names:
                names.append(parent.name)
            for v in bridge:
                v[deform][names.index(parent.name)] = 1.0
        if b.name not in names:
            names.append(b.name)
        gi = names.index(b.name)
        mat = 1 if b.name in limb_bones else 0
        for v in verts:        # ops reuse freed slots: weight the verts they return, not an index range
            v[deform][gi] = 1.0
            for f in v.link_faces:
                f.material_index = mat
    me = bpy.data.meshes.new(f"{arm_obj.name}_sticks")
    bm.to_mesh(me)
    bm.free()
    for m in mats:
        me.materials.append(m)
    for p in me.polygons:
        p.use_smooth = True
    obj = bpy.data.objects.new(me.name, me)
    bpy.context.scene.collection.objects.link(obj)
    for name in names:
        obj.vertex_groups.new(name=name)
    obj.parent = arm_obj
    mod = obj.modifiers.new("Armature", 'ARMATURE')
    mod.object = arm_obj
    return obj


def poly_curve(name, points, radius, mat, cyclic=False):
    cu = bpy.data.curves.new(name, 'CURVE')
    cu.dimensions = '3D'
    cu.bevel_depth = radius
    cu.bevel_resolution = 2
    sp = cu.splines.new('POLY')
    sp.points.add(len(points) - 1)
    sp.points.foreach_set("co", np.c_[points, np.ones(len(points))].astype(np.float32).ravel())
    sp.use_cyclic_u = cyclic
    cu.materials.append(mat)
    obj = bpy.data.objects.new(name, cu)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def text(body, location, size, mat, yaw=0.0, align='CENTER'):
    cu = bpy.data.curves.new("caption", 'FONT')
    cu.body = body
    cu.size = size
    cu.align_x = align
    cu.materials.append(mat)
    obj = bpy.data.objects.new("caption", cu)
    obj.location = location
    obj.rotation_euler = (math.pi / 2, 0.0, yaw)      # face the camera
    bpy.context.scene.collection.objects.link(obj)
    return obj


def guides(res, swivel, offset, mats):
    """Shoulder-wrist / hip-ankle axes and swivel circles of the edited limbs, plus target markers."""
    pos, wrot = res.fk()
    L = res.body.limb_lengths()
    phi = np.linspace(0, 2 * np.pi, 73)[:-1]
    for li, (_, b, m, e) in enumerate(sk.LIMBS):
        if li == 3:
            continue
        base, end = pos[0, b], pos[0, e]
        poly_curve("axis", np.stack([base, end]) + offset, 0.004, mats["axis"])
        ring = ls.mid_from_swivel(np.broadcast_to(base, (72, 1, 3)), np.broadcast_to(end, (72, 1, 3)),
                                  phi[:, None], L[[li]], np.broadcast_to(wrot[0, sk.PARENTS[b]], (72, 1, 3, 3)),
                                  limb_ids=[li])[:, 0]
        poly_curve("swivel_circle", ring + offset, 0.003, mats["axis"], cyclic=True)
    for j in ls.LIMB_END:
        bpy.ops.mesh.primitive_cube_add(size=0.05, location=pos[0, j] + offset)
        bpy.context.active_object.data.materials.append(mats["target"])


def render_still(scene, out, width, height):
    """Render ``scene`` with the Workbench engine (studio light, material colours, outlines, white
    world) to the PNG ``out`` (RGB, ``width`` x ``height``); returns its absolute path."""
    scene.render.engine = 'BLENDER_WORKBENCH'
    scene.display.shading.light = 'STUDIO'
    scene.display.shading.color_type = 'MATERIAL'
    scene.display.shading.show_object_outline = True
    scene.display.shading.show_cavity = True
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    scene.world.color = (1.0, 1.0, 1.0)
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = 'PNG'
    scene.render.image_settings.color_mode = 'RGB'
    scene.render.image_settings.compression = 100
    scene.view_settings.view_transform = 'Standard'
    out_path = os.path.abspath(out)
    os.makedirs(os.path.dirname(out_path), exist_ok=True)
    scene.render.filepath = out_path
    bpy.ops.render.render(write_still=True)
    return out_path


def main():
    args = _args()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = 24, 1.0
    mats = {"body": _material("body", (0.72, 0.72, 0.70)), "limb": _material("limb", (0.20, 0.45, 0.85)),
            "axis": _material("axis", (0.15, 0.15, 0.15)), "target": _material("target", (0.95, 0.45, 0.10)),
            "text": _material("text", (0.05, 0.05, 0.05))}
    res = figure_pose()
    figures = []
    for k, delta in enumerate((np.zeros(4), DELTA)):
        out = writer.write_result(res, writer.WriteOptions(frame_start=1, armature_name=f"figure{k}"))
        obj = out.armature
        live_rig.build_live_rig(obj, res)
        for li, limb in enumerate(sk.LIMB_NAMES):       # a Graph-Editor style edit of the swivel key
            fc = live_rig.swivel_fcurve(obj, limb)
            kp = fc.keyframe_points[0]
            kp.co[1] += float(delta[li])
            kp.handle_left[1] += float(delta[li])
            kp.handle_right[1] += float(delta[li])
            fc.update()
        offset = np.array([k * GAP, 0.0, 0.0])
        obj.location = offset
        obj.show_in_front = False
        obj.hide_render = True
        stick_mesh(obj, [mats["body"], mats["limb"]])
        guides(res, None, offset, mats)
        figures.append(obj)
    scene.frame_set(1)
    yaw = math.radians(-28.0)
    text("swivel as solved", (0.0, -0.3, -0.12), 0.09, mats["text"], yaw)
    text("elbows \u00b170\u00b0, left knee \u221250\u00b0", (GAP, -0.3, -0.12), 0.09, mats["text"], yaw)
    text("MANIKIN live swivel rig", (GAP / 2, -0.3, 2.12), 0.1, mats["text"], yaw)
    text("same hand / foot targets (orange); elbows and knees turn about the",
         (GAP / 2, -0.3, 2.0), 0.06, mats["text"], yaw)
    text("shoulder-wrist / hip-ankle axis (lines) on their swivel circles",
         (GAP / 2, -0.3, 1.92), 0.06, mats["text"], yaw)

    cam_data = bpy.data.cameras.new("camera")
    cam_data.type = 'ORTHO'
    cam_data.ortho_scale = 3.9
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    target = np.array([GAP / 2, 0.0, 1.0])
    cam.location = target + 6.0 * np.array([math.sin(yaw), -math.cos(yaw), 0.12])
    cam.rotation_euler = (math.radians(83.0), 0.0, yaw)
    scene.camera = cam

    out_path = render_still(scene, args.out, args.width, args.height)
    print(f"wrote {out_path} ({os.path.getsize(out_path) // 1024} KB)")


if __name__ == "__main__":
    main()
