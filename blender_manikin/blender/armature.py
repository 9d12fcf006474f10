"""The body armature: bone layout, rolls, and body-model → pose-bone rotations.

Axes and units: Blender world / armature space (the armature object is
created at the origin with an identity transform), metres, +Z up, the body
faces -Y, performer's left = +X -- the same as :mod:`blender_manikin.core.skeleton`.

Bones
-----
One bone per joint, named exactly as :data:`skeleton.JOINT_NAMES`, parented as
:data:`skeleton.PARENTS`.  The bone *head* is the joint's rest position
(``body.rest_positions()``); the *tail* points at the joint's child (pelvis →
spine1, spine3 → neck, otherwise the only child).  Leaf bones use
:func:`blender_manikin.core.export_bvh.end_site_offsets`: ``head`` points up
(+Z, 0.09 stature), the wrists continue along the forearm (±X, 0.10 stature)
and the feet point forward (-Y, 0.04 stature).  A bone whose head coincides
with its parent's tail is connected (``use_connect``).

Rolls (bone-local axes; Blender bones have local +Y along head → tail)
-----------------------------------------------------------------------
Each bone's local X axis is chosen (then orthogonalised against Y) as:

==========================================  ================  ==================
bones                                       local X (world)   local Z (world)
==========================================  ================  ==================
pelvis, spine1-3, neck, head                +X (perf. left)   -Y (forward)
left_collar/shoulder/elbow/wrist            -Z (down)         -Y (forward)
right_collar/shoulder/elbow/wrist           +Z (up)           -Y (forward)
left/right hip, knee, ankle, foot           +X (perf. left)   +Y (back) for thigh/shank
==========================================  ================  ==================

These are the hinge axes of :mod:`blender_manikin.core.limb_solver` (``H0``),
so **elbows and knees flex about the bone's local +X axis, positive angle =
flexion**, and their only other motion (elbow pronation/supination) is a
twist about local Y.  On the torso and legs +X is the performer's left for
every bone, so a positive X rotation is the same sagittal rotation
everywhere: spine / neck / head bend forward, hips extend (thigh back), knees
flex, ankles plantar-flex.  On the arms a positive X rotation swings the
segment forward (horizontal flexion at the shoulder, flexion at the elbow).
Left and right rolls are mirror images in Blender's sense (X-Mirror /
Symmetrize produce the same rolls).

Rotation mapping
----------------
The body model's joint frames are world-aligned at rest: ``R_world[j] =
R_world[p] @ R_local[j]`` with identity = rest.  A bone with rest matrix
``B_j`` (3x3, armature space, columns = bone X, Y, Z) posed by the
body model must have the armature-space orientation ``M_j = R_world[j] B_j``
(it rotates rigidly with its joint).  Blender composes ``M_j = M_p B_pᵀ B_j Q_j``
(``Q_j`` = pose-bone rotation, ``matrix_basis``), so

    R_world[j] B_j = R_world[p] B_p B_pᵀ B_j Q_j = R_world[p] B_j Q_j
    ⇒  Q_j = B_jᵀ R_world[p]ᵀ R_world[j] B_j = B_jᵀ R_local[j] B_j,

and the same with ``R_world[p] = I`` for the root.  Translations follow
because bone heads sit at the joint rest positions.  The root bone's location
channel is in its own rest frame: ``head = head_rest + B_0 @ loc``, so
``loc = B_0ᵀ (root_pos - head_rest)``.
"""
from __future__ import annotations

import numpy as np

from ..core import rotations as rot
from ..core import skeleton as sk
from ..core.export_bvh import end_site_offsets

#: the joint whose head is each bone's tail (None for leaf bones)
TAIL_CHILD = {
    "pelvis": "spine1", "left_hip": "left_knee", "right_hip": "right_knee",
    "spine1": "spine2", "left_knee": "left_ankle", "right_knee": "right_ankle",
    "spine2": "spine3", "left_ankle": "left_foot", "right_ankle": "right_foot",
    "spine3": "neck", "left_foot": None, "right_foot": None, "neck": "head",
    "left_collar": "left_shoulder", "right_collar": "right_shoulder", "head": None,
    "left_shoulder": "left_elbow", "right_shoulder": "right_elbow",
    "left_elbow": "left_wrist", "right_elbow": "right_wrist",
    "left_wrist": None, "right_wrist": None,
}

_LEFT_ARM = ("left_collar", "left_shoulder", "left_elbow", "left_wrist")
_RIGHT_ARM = ("right_collar", "right_shoulder", "right_elbow", "right_wrist")


def _preferred_x():
    x = np.tile([1.0, 0.0, 0.0], (sk.NUM_JOINTS, 1))
    for n in _LEFT_ARM:
        x[sk.J[n]] = [0.0, 0.0, -1.0]
    for n in _RIGHT_ARM:
        x[sk.J[n]] = [0.0, 0.0, 1.0]
    return x


#: ``(22, 3)`` preferred local X axis of each bone in armature space (see module doc)
PREFERRED_X = _preferred_x()

#: custom property on the armature object: JSON list of the body offsets (22x3 m)
PROP_BODY = "manikin_body"
#: custom property marking an armature made by this add-on
PROP_MARK = "manikin_armature"


def bone_layout(body: sk.Body):
    """Rest layout of the armature for ``body``.

    Returns ``(heads, tails, rest_mats, connect)``: heads/tails ``(22, 3)``
    metres (armature space), ``rest_mats`` ``(22, 3, 3)`` bone rest rotations
    ``B`` (columns = bone X, Y, Z), ``connect`` ``(22,)`` bool.
    """
    heads = body.rest_positions()
    tails = np.empty_like(heads)
    connect = np.zeros(sk.NUM_JOINTS, dtype=bool)
    leaf = end_site_offsets(body)
    for j, name in enumerate(sk.JOINT_NAMES):
        child = TAIL_CHILD[name]
        tip = heads[sk.J[child]] if child is not None else heads[j] + leaf[j]
        if np.linalg.norm(tip - heads[j]) < 1e-4:   # degenerate: keep the bone alive
            tip = heads[j] + np.array([0.0, 0.0, 0.02 * body.stature])
        tails[j] = tip
    for j in range(1, sk.NUM_JOINTS):
        p = sk.PARENTS[j]
        connect[j] = TAIL_CHILD[sk.JOINT_NAMES[p]] == sk.JOINT_NAMES[j]
    y = rot.normalize(tails - heads)
    x = PREFERRED_X - np.sum(PREFERRED_X * y, -1, keepdims=True) * y
    bad = np.linalg.norm(x, axis=-1) < 1e-6      # bone along its preferred X: fall back
    if np.any(bad):
        alt = np.where(np.abs(y[bad, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        x[bad] = np.cross(y[bad], alt)
    x = rot.normalize(x)
    z = np.cross(x, y)
    rest_mats = np.stack([x, y, z], axis=-1)
    return heads, tails, rest_mats, connect


def pose_bone_quaternions(local_rot, rest_mats):
    """Pose-bone quaternions ``Q = Bᵀ R_local B`` for keying.

    local_rot: ``(T, 22, 3, 3)`` body-model local rotations; rest_mats:
    ``(22, 3, 3)`` bone rest rotations (armature space).  Returns ``(T, 22, 4)``
    float64 (w, x, y, z), sign-continuous over time (consecutive samples of a
    bone have a non-negative dot product) so interpolation takes the short way.
    """
    B = np.asarray(rest_mats, dtype=np.float64)
    # in quaternions: q(Bᵀ R B) = q_B* q_R q_B (cheaper than 3x3 products on (T, 22))
    qR = rot.matrix_to_quat(np.asarray(local_rot, dtype=np.float64))
    qB = rot.matrix_to_quat(B)
    q = rot.quat_mul(rot.quat_mul(rot.quat_conj(qB)[None], qR), qB[None])
    return rot.quat_continuous(q, axis=0)


def root_locations(root_pos, rest_head, rest_mat):
    """Root bone location channel ``(T, 3)`` = ``B_0ᵀ (root_pos - head_rest)``.

    root_pos: ``(T, 3)`` metres, armature space; rest_head ``(3,)``; rest_mat ``(3, 3)``.
    """
    d = np.asarray(root_pos, np.float64) - np.asarray(rest_head, np.float64)
    return d @ np.asarray(rest_mat, np.float64)


# --------------------------------------------------------------------------
# Blender side
def _unique_name(collection, base):
    if base not in collection:
        return base
    i = 1
    while f"{base}.{i:03d}" in collection:
        i += 1
    return f"{base}.{i:03d}"


def create_armature(body: sk.Body, name: str = "MANIKIN_body", collection=None, context=None):
    """Create a NEW armature object for ``body`` and return it.

    The object and its data get unique names derived from ``name`` (existing
    objects are never reused or modified); it is linked to ``collection``
    (default: the scene's master collection) at the origin with an identity
    transform, in object mode, and becomes the active, selected object.
    Every pose bone uses quaternion rotation.  The body offsets are stored
    as a custom property (``manikin_body``) so a later solve can tell whether
    the armature fits its body.
    """
    import bpy
    from mathutils import Vector

    context = context or bpy.context
    scene = context.scene
    view_layer = context.view_layer
    if collection is None:
        collection = scene.collection
    heads, tails, rest_mats, connect = bone_layout(body)

    prev_active = view_layer.objects.active
    if prev_active is not None and prev_active.mode != 'OBJECT':
        bpy.ops.object.mode_set(mode='OBJECT')

    arm = bpy.data.armatures.new(_unique_name(bpy.data.armatures, name))
    obj = bpy.data.objects.new(_unique_name(bpy.data.objects, name), arm)
    try:
        collection.objects.link(obj)
        arm.display_type = 'OCTAHEDRAL'
        obj.show_in_front = True
        for o in view_layer.objects:
            if o.select_get():
                o.select_set(False)
        view_layer.objects.active = obj
        obj.select_set(True)
        bpy.ops.object.mode_set(mode='EDIT')
        try:
            ebones = []
            for j, jname in enumerate(sk.JOINT_NAMES):
                eb = arm.edit_bones.new(jname)
                eb.head = Vector(heads[j])
                eb.tail = Vector(tails[j])
                eb.align_roll(Vector(rest_mats[j][:, 2]))
                ebones.append(eb)
            for j in range(1, sk.NUM_JOINTS):
                ebones[j].parent = ebones[sk.PARENTS[j]]
                ebones[j].use_connect = bool(connect[j])
        finally:
            bpy.ops.object.mode_set(mode='OBJECT')
        for pb in obj.pose.bones:
            pb.rotation_mode = 'QUATERNION'
        obj[PROP_MARK] = 1
        obj[PROP_BODY] = [float(v) for v in np.concatenate([body.offsets.ravel(), body.root_rest])]
    except Exception:
        bpy.data.objects.remove(obj)
        bpy.data.armatures.remove(arm)
        raise
    return obj


def rest_matrices(obj):
    """``(heads (22, 3), rest_mats (22, 3, 3))`` read back from the armature ``obj``'s bones.

    Raises ``KeyError`` naming a joint whose bone is missing.
    """
    bones = obj.data.bones
    heads = np.empty((sk.NUM_JOINTS, 3))
    mats = np.empty((sk.NUM_JOINTS, 3, 3))
    for j, name in enumerate(sk.JOINT_NAMES):
        b = bones.get(name)
        if b is None:
            raise KeyError(f"armature {obj.name!r} has no bone {name!r}")
        m = np.array(b.matrix_local, dtype=np.float64)
        heads[j] = m[:3, 3]
        mats[j] = rot.orthonormalize(m[:3, :3])
    return heads, mats


def armature_matches_body(obj, body: sk.Body, tol: float = 1e-4) -> bool:
    """True when ``obj`` is a MANIKIN armature built for a body equal to ``body`` (every bone offset
    and rest head within ``tol`` m; 0.1 mm by default: the same take solved again at another scene
    frame rate is calibrated on resampled frames, its body a few hundredths of a millimetre off)."""
    if obj is None or getattr(obj, "type", None) != 'ARMATURE' or PROP_BODY not in obj.keys():
        return False
    try:
        stored = np.asarray(list(obj[PROP_BODY]), dtype=np.float64)
        ref = np.concatenate([body.offsets.ravel(), body.root_rest])
        if stored.shape != ref.shape or np.max(np.abs(stored - ref)) > tol:
            return False
        heads, _ = rest_matrices(obj)
    except (KeyError, TypeError, ValueError):
        return False
    return bool(np.max(np.abs(heads - body.rest_positions())) < tol)
