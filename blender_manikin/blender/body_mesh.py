"""The mannequin mesh on a solved armature (:mod:`..core.mannequin` gives its shape).

A mesh object ``<armature>_mannequin``, child of the armature, in the armature's collections,
skinned rigidly to its body bones (one vertex group per bone, weight 1, an Armature modifier), so
it follows the solve, the live swivel rig and any edit of the keys.  It carries the material
``MANIKIN mannequin`` (made once; a user's changes to it are kept) and the mark
:data:`PROP_MESH`, by which a later solve or bake finds it.  It is built in the armature's rest
space, in the scene's unit (the body passed in is already in it).
"""
from __future__ import annotations

import bpy

from ..core.mannequin import mannequin_mesh
from ..core.skeleton import J

#: custom property marking the mannequin mesh object this module made
PROP_MESH = "manikin_mannequin"
#: the material the mannequins share
MATERIAL = "MANIKIN mannequin"
#: its colour: light wood, apart from Blender's grey meshes and its orange selection outline
COLOUR = (0.72, 0.60, 0.45, 1.0)


def find_body_mesh(armature_obj):
    """The mannequin this module made on ``armature_obj`` (a child object with
    :data:`PROP_MESH`), or None."""
    for child in armature_obj.children:
        if child.type == 'MESH' and child.get(PROP_MESH):
            return child
    return None


def _material(created):
    mat = bpy.data.materials.get(MATERIAL)
    if mat is not None:
        return mat
    mat = bpy.data.materials.new(MATERIAL)
    created.append(mat)
    mat.diffuse_color = COLOUR                       # the Solid view's colour
    mat.roughness = 0.6
    if getattr(mat, "node_tree", None) is not None:    # rendered: the default Principled BSDF
        bsdf = mat.node_tree.nodes.get("Principled BSDF")
        if bsdf is not None:
            bsdf.inputs["Base Color"].default_value = COLOUR
    return mat


def add_body_mesh(armature_obj, body, context=None, created=None):
    """Add the mannequin of ``body`` (:class:`~..core.skeleton.Body`, in the scene's unit: the
    body the armature was built from) to ``armature_obj``; returns the new mesh object.  The
    IDs it makes (object, mesh, the material if it was missing) are appended to ``created``, for
    the caller to remove them again if a later step fails."""
    context = context or bpy.context
    created = created if created is not None else []
    m = mannequin_mesh(body)
    name = f"{armature_obj.name}_mannequin"
    me = bpy.data.meshes.new(name)
    created.append(me)
    polys = [tuple(int(i) for i in (f[:3] if f[3] == f[2] else f)) for f in m.faces]
    me.from_pydata(m.verts.tolist(), [], polys)
    if hasattr(me, "shade_smooth"):              # Blender 4.1+
        me.shade_smooth()
    else:
        me.polygons.foreach_set("use_smooth", [True] * len(me.polygons))
    me.update()
    me.materials.append(_material(created))
    obj = bpy.data.objects.new(name, me)
    created.append(obj)
    for coll in (armature_obj.users_collection or (context.scene.collection,)):
        coll.objects.link(obj)
    obj.parent = armature_obj                     # the armature's space: it moves with it
    obj[PROP_MESH] = 1
    for bone in m.bone_names:
        idx = [int(i) for i in (m.bone == J[bone]).nonzero()[0]]
        obj.vertex_groups.new(name=bone).add(idx, 1.0, 'REPLACE')
    mod = obj.modifiers.new("Armature", 'ARMATURE')
    mod.object = armature_obj
    mod.use_vertex_groups = True
    mod.use_bone_envelopes = False
    return obj


def copy_body_mesh(src_armature, dst_armature, context=None):
    """Give ``dst_armature`` (a copy of ``src_armature``'s bones, e.g. a bake) a copy of the
    mannequin on ``src_armature``; returns it, or None when the source has none."""
    context = context or bpy.context
    src = find_body_mesh(src_armature)
    if src is None:
        return None
    obj = src.copy()                               # shares the mesh data; groups, modifiers copied
    obj.name = f"{dst_armature.name}_mannequin"
    for coll in (dst_armature.users_collection or (context.scene.collection,)):
        coll.objects.link(obj)
    obj.parent = dst_armature
    obj.matrix_parent_inverse = src.matrix_parent_inverse.copy()
    for mod in obj.modifiers:
        if mod.type == 'ARMATURE' and mod.object == src_armature:
            mod.object = dst_armature
    return obj

