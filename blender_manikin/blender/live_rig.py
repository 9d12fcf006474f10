"""Live swivel rig: edit an elbow or knee by its swivel angle, with Blender's own constraints.

A solve builds this rig by default (``blender/solve_job.py``: the rig's
action is then the only one keyed; a solve without it, or the "Make Live"
operator on an existing FK action, gives FK keys on every bone first).  The
*live* form built by :func:`build_live_rig` keeps the torso, head, collars
and toes on FK keys but drives the limbs with constraints, so the animator
changes a limb by its swivel angle (a keyed custom property) or by grabbing a
hand / foot control, and the hand / foot stays exactly where it is.
Everything is stored in the .blend: constraints and *simple-expression*
drivers, which Blender evaluates without Python (no auto-run scripts, no
add-on needed), in the viewport, during playback, in renders and in
``blender -b`` scripts calling ``frame_set``.

Axes and units: armature space = Blender world axes when the armature object
has an identity transform (metres, +Z up, the body faces -Y, performer's
left = +X; see :mod:`blender_manikin.core.skeleton`).  Angles are radians
(custom properties have subtype ANGLE, so the UI shows degrees).

Bones added per limb (``.L`` / ``.R``; arms shown, legs use ``foot``,
``leg``, ``thigh``, ``shin``), none of them deforming:

==========================  ================================================
``ctrl_hand.L``             hand target: no parent, animated in armature
                            space; head = wrist joint, rest orientation =
                            the wrist bone's (1.6x longer so it can be picked)
``MCH-arm_swivel.L``        at the shoulder, parented to the collar (pelvis
                            for legs), rest direction (bone +Y) = ``N0`` of
                            the limb, rest +Z = ``U0`` made orthogonal to
                            ``N0``; pose Euler Y = the swivel angle (driver
                            ``swivel`` on ``["swivel_left_arm"]``), then a
                            Damped Track to ``ctrl_hand.L``
``MCH-arm_pole.L``          child of the above, rest head = shoulder + ``D``
                            ``U0``: the IK pole
``MCH-upper_arm.L``         copies of the shoulder / elbow bones forming the
``MCH-forearm.L``           IK chain (IK on the forearm)
==========================  ================================================

Why this reproduces :mod:`blender_manikin.core.limb_solver` exactly
-------------------------------------------------------------------
* The swivel bone's pose before its constraint is ``R_par B_ref Rot_Y(φ)``
  (``R_par`` = world rotation of the collar / pelvis joint, ``B_ref`` its rest
  frame: Y = ``n0``, Z = ``u0``).  Damped Track applies the *minimal* world
  rotation taking its Y axis ``R_par n0`` to ``n`` (shoulder → hand
  control), which is ``R_par swing(n0 → R_parᵀ n) R_parᵀ``.  So its Z axis
  is ``R_par swing(n0 → R_parᵀ n) Rot(n0, φ) u0 = cos φ u + sin φ v`` with
  ``u, v`` of :func:`~blender_manikin.core.limb_solver.swivel_frame`: the
  pole sits exactly in the direction the elbow must bend towards.
* Blender's IK solver (``intern/iksolver``, ``ConstrainPoleVector``) applies
  the pole once, before iterating: it rotates the chain about the shoulder
  so the chain's end points at the goal and the chain root's
  ``up = X cos(pole_angle) + Z sin(pole_angle)`` (projected perpendicular to
  the goal direction) points at the pole.  With ``pole_angle = -π/2``,
  ``up = -Z_upper``, whose perpendicular part is exactly the elbow's bend
  direction for *any* elbow flexion (the forearm flexes about the upper
  arm's +X, positive = flexion).  Other pole angles mix X and a Z shortened
  by ``cos α`` (α = angle between upper arm and shoulder-wrist axis), so
  driving ``pole_angle`` with the swivel would be non-linear in the swivel;
  the swivel therefore rotates the pole *bone* and ``pole_angle`` stays at
  :data:`POLE_ANGLE`.
* The MCH forearm / shin's pose channel (Euler X, the hinge) is driven by
  the law of cosines from the base-control distance (a simple-expression
  driver with a Distance variable, :func:`flexion_expression`), so the
  chain the IK starts from already has the right flexion: the pole
  pre-rotation puts its end exactly on the target and the iterations
  (Blender stops once an update is below 1e-3 rad) have nothing left to
  do.  Without it the result is only as good as the solver tolerance
  (~0.07 mm), with it float precision (~0.003 mm).  The IK stays the
  mechanism (and keeps the hinge in ``[0, FLEX_MAX]`` about local X, with
  Y / Z locked) so the rig reads like any IK arm.  ``use_stretch`` is off:
  out-of-reach targets get a fully extended limb pointing at them, too
  close ones the most flexed limb, as in ``solve_limbs``.
* Deform shoulder / elbow copy the MCH chain (Copy Transforms, world space);
  the elbow then adds the forearm pronation ``τ`` of ``solve_limbs``
  (a Transformation constraint: swing-twist-Y of the hand control measured
  in the MCH forearm's space, clamped to ``TWIST_RANGE``, applied after the
  hinge: ``R_elbow_local = Rot(X, θ) Rot(Y, τ)``); the wrist / ankle copies
  the control's world rotation (Copy Rotation), so the hand / foot
  orientation is exact.

Keys (:func:`build_live_rig`, a NEW action): torso, head, collars and toes
(``pose.bones[...].rotation_quaternion``, pelvis ``location``) from the
result's FK, the controls' location / rotation (the result's wrist and ankle
world poses), the swivel properties ``["swivel_<limb>"]`` and a hidden,
locked copy ``["swivel_solved_<limb>"]`` that :func:`reset_swivel` restores.
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

import bpy

from ..core import limb_solver as ls
from ..core import plain
from ..core import rotations as rot
from ..core import skeleton as sk
from ..core.pose_result import PoseResult
from . import armature as arm_mod
from . import keying
from . import writer

#: IK pole angle (radians): the upper arm / thigh's -Z axis points at the pole
POLE_ANGLE = -math.pi / 2
#: maximum IK iterations (Blender stops earlier once an update is below 1e-3 rad)
IK_ITERATIONS = 1000
#: control bones are this many times longer than the wrist / ankle bone
CTRL_LENGTH = 1.6
#: object custom property marking a live rig (value: format version)
PROP_LIVE = "manikin_live_rig"
#: limb name -> keyed custom property holding the solved swivel (for "reset")
SOLVED_PROPS = {limb: f"swivel_solved_{limb}" for limb in sk.LIMB_NAMES}
SOLVED_GROUP = "Swivel (solved)"
CTRL_GROUP = "Controls"
#: bone collections (Blender 4.0+)
COLL_CTRL = "MANIKIN controls"
COLL_MCH = "MANIKIN mechanism"
#: constraint names (all prefixed so they can be found again)
CON_PREFIX = "MANIKIN "
#: the names (less :data:`CON_PREFIX`) of every constraint the live rigs add: only constraints of
#: these full names are the rig's (:func:`is_rig_constraint`); an animator's own ``MANIKIN mine``
#: is left alone when a rig is rebuilt, muted or removed
CON_NAMES = ("swivel track", "IK", "follow IK", "pronation", "twist share", "hand rotation", "foot rotation")
_CON_FULL = frozenset(CON_PREFIX + n for n in CON_NAMES)


def is_rig_constraint(con) -> bool:
    """True for a constraint a live rig added (named ``MANIKIN <one of CON_NAMES>``)."""
    return con.name in _CON_FULL


@dataclass(frozen=True)
class LimbRig:
    """Names of one limb's bones in the live rig."""
    limb: str        # "left_arm", ...
    index: int       # index in sk.LIMB_NAMES
    is_arm: bool
    base: str        # deform bones (joint names)
    mid: str
    end: str
    parent: str      # joint the limb hangs from (collar / pelvis)
    ctrl: str        # hand / foot control
    ref: str         # swivel reference (Damped Track + swivel rotation)
    pole: str        # IK pole (child of ref)
    upper: str       # MCH IK chain
    lower: str


def _limb_rigs():
    out = []
    for li, (limb, b, m, e) in enumerate(sk.LIMBS):
        s = "L" if limb.startswith("left") else "R"
        arm = limb.endswith("arm")
        kind = "arm" if arm else "leg"
        out.append(LimbRig(
            limb=limb, index=li, is_arm=arm, base=sk.JOINT_NAMES[b], mid=sk.JOINT_NAMES[m],
            end=sk.JOINT_NAMES[e], parent=sk.JOINT_NAMES[sk.PARENTS[b]],
            ctrl=f"ctrl_{'hand' if arm else 'foot'}.{s}", ref=f"MCH-{kind}_swivel.{s}",
            pole=f"MCH-{kind}_pole.{s}", upper=f"MCH-{'upper_arm' if arm else 'thigh'}.{s}",
            lower=f"MCH-{'forearm' if arm else 'shin'}.{s}"))
    return tuple(out)


#: the four limbs in sk.LIMB_NAMES order
LIMB_RIGS = _limb_rigs()
#: joints keyed as FK in the live action (everything not driven by a limb rig)
FK_JOINTS = tuple(n for n in sk.JOINT_NAMES
                  if n not in {x for r in LIMB_RIGS for x in (r.base, r.mid, r.end)})
#: every bone the live rig adds
RIG_BONES = tuple(n for r in LIMB_RIGS for n in (r.ctrl, r.ref, r.pole, r.upper, r.lower))


def is_live_rig(obj) -> bool:
    """True when ``obj`` is an armature converted by :func:`build_live_rig`."""
    return (obj is not None and getattr(obj, "type", None) == 'ARMATURE'
            and PROP_LIVE in obj.keys() and all(r.ctrl in obj.data.bones for r in LIMB_RIGS))


def _u0_perp(li):
    """``U0`` of limb ``li`` made orthogonal to ``N0`` (unit)."""
    n0, u0 = ls.N0[li], ls.U0[li]
    return rot.normalize(u0 - np.dot(u0, n0) * n0)


# --------------------------------------------------------------------------
# edit-mode helpers
def free_edit_bone(eb, name: str):
    """Edit bone ``name`` of ``eb`` (an armature's ``edit_bones``), created if missing, made a
    free helper: not deforming, unparented, unconnected. Head, tail and roll are the caller's."""
    b = eb.get(name)
    if b is None:
        b = eb.new(name)
    b.use_deform = False
    b.use_connect = False
    b.parent = None
    return b


@contextmanager
def _edit_mode(obj, context):
    """Enter edit mode on ``obj`` (made active), yield its edit bones, restore the previous state."""
    view_layer = context.view_layer
    if obj.name not in view_layer.objects:
        view_layer.update()            # objects linked just now appear after a resync
    if obj.name not in view_layer.objects:
        raise RuntimeError(f"armature {obj.name!r} is not in the view layer; link it to the scene first")
    prev_active = view_layer.objects.active
    prev_sel = [o for o in view_layer.objects if o.select_get()]
    prev_mode = prev_active.mode if prev_active is not None else 'OBJECT'
    if prev_active is not None and prev_mode != 'OBJECT':
        bpy.ops.object.mode_set(mode='OBJECT')
    hidden = obj.hide_get()
    hide_vp = obj.hide_viewport
    obj.hide_set(False)
    obj.hide_viewport = False
    view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode='EDIT')
    try:
        yield obj.data.edit_bones
    finally:
        bpy.ops.object.mode_set(mode='OBJECT')
        obj.hide_viewport = hide_vp
        obj.hide_set(hidden)
        for o in view_layer.objects:
            o.select_set(o in prev_sel)
        view_layer.objects.active = prev_active
        if prev_active is not None and prev_mode != 'OBJECT' and prev_active.mode != prev_mode:
            try:
                bpy.ops.object.mode_set(mode=prev_mode)
            except RuntimeError:
                pass


# --------------------------------------------------------------------------
# building the rig
def _body_from_object(obj):
    stored = np.asarray(list(obj[arm_mod.PROP_BODY]), dtype=np.float64)
    return sk.Body.from_offsets(stored[:sk.NUM_JOINTS * 3], stored[sk.NUM_JOINTS * 3:])


def _create_bones(obj, context):
    """Add (or re-place) the control / mechanism bones of every limb in edit mode."""
    from mathutils import Vector

    arm = obj.data
    with _edit_mode(obj, context) as eb:
        for name in set(x for r in LIMB_RIGS for x in (r.base, r.mid, r.end, r.parent)):
            if name not in eb:
                raise KeyError(f"armature {obj.name!r} has no bone {name!r}")
        for r in LIMB_RIGS:
            base, mid, end = eb[r.base], eb[r.mid], eb[r.end]
            l1 = (mid.head - base.head).length
            l2 = (end.head - mid.head).length

            def new(name):
                return free_edit_bone(eb, name)

            # hand / foot control: same rest frame as the wrist / ankle, longer
            c = new(r.ctrl)
            c.head = end.head.copy()
            c.tail = end.head + (end.tail - end.head) * CTRL_LENGTH
            c.roll = end.roll
            # swivel reference at the limb base, rest +Y = N0, +Z = U0 (orthogonal part)
            n0 = Vector(ls.N0[r.index])
            u0 = Vector(_u0_perp(r.index))
            ref = new(r.ref)
            ref.head = base.head.copy()
            ref.tail = base.head + n0 * (0.5 * l1)
            ref.align_roll(u0)
            ref.parent = eb[r.parent]
            pole = new(r.pole)
            # pole offset along the reference bone's rest Z (= u0 up to rounding)
            z = Vector(np.array(ref.matrix)[:3, 2])
            pole.head = base.head + z * (l1 + l2)
            pole.tail = pole.head + n0 * (0.1 * l1)
            pole.align_roll(u0)
            pole.parent = ref
            # MCH IK chain: copies of the deform limb bones
            up = new(r.upper)
            up.head, up.tail, up.roll = base.head.copy(), base.tail.copy(), base.roll
            up.parent = eb[r.parent]
            up.use_connect = base.use_connect
            lo = new(r.lower)
            lo.head, lo.tail, lo.roll = mid.head.copy(), mid.tail.copy(), mid.roll
            lo.parent = up
            lo.use_connect = True
    _bone_collections(obj)
    return arm


def _bone_collections(obj):
    """Put controls and mechanism bones into their own bone collections (Blender 4.0+)."""
    arm = obj.data
    if "collections" not in arm.bl_rna.properties:
        return
    colls = arm.collections
    ctrl = colls.get(COLL_CTRL) or colls.new(COLL_CTRL)
    mch = colls.get(COLL_MCH) or colls.new(COLL_MCH)
    mch.is_visible = False
    for r in LIMB_RIGS:
        for name in (r.ctrl,):
            ctrl.assign(arm.bones[name])
        for name in (r.ref, r.pole, r.upper, r.lower):
            mch.assign(arm.bones[name])
    for r in LIMB_RIGS:
        b = arm.bones[r.ctrl]
        if hasattr(b, "color"):
            b.color.palette = 'THEME09' if r.limb.startswith("left") else 'THEME04'


def _constraint(pb, ctype, name):
    """A constraint named ``CON_PREFIX + name`` on pose bone ``pb`` (existing ones are replaced);
    ``name`` one of :data:`CON_NAMES`."""
    if name not in CON_NAMES:
        raise ValueError(f"live rig constraint {name!r} is not in CON_NAMES")
    full = CON_PREFIX + name
    old = pb.constraints.get(full)
    if old is not None:
        pb.constraints.remove(old)
    c = pb.constraints.new(ctype)
    c.name = full
    return c


def _clear_rig_constraints(obj):
    for pb in obj.pose.bones:
        for c in list(pb.constraints):
            if is_rig_constraint(c):
                pb.constraints.remove(c)


def _swivel_driver(obj, pb, limb):
    """Driver ``rotation_euler[1] = swivel`` (simple expression) on the reference bone ``pb``."""
    path = f'pose.bones["{pb.name}"].rotation_euler'
    if obj.animation_data is not None:
        for fc in list(obj.animation_data.drivers):
            if fc.data_path == path and fc.array_index == 1:
                obj.animation_data.drivers.remove(fc)
    fc = pb.driver_add("rotation_euler", 1)
    for m in list(fc.modifiers):
        fc.modifiers.remove(m)
    drv = fc.driver
    drv.type = 'SCRIPTED'
    for v in list(drv.variables):
        drv.variables.remove(v)
    var = drv.variables.new()
    var.name = "swivel"
    var.type = 'SINGLE_PROP'
    var.targets[0].id_type = 'OBJECT'
    var.targets[0].id = obj
    var.targets[0].data_path = f'["{writer.SWIVEL_PROPS[limb]}"]'
    drv.expression = "swivel"
    return fc


def flexion_expression(l1: float, l2: float, flex_max: float) -> str:
    """Simple driver expression of the hinge flexion θ (radians) from the base-end distance ``d``.

    ``θ = π - acos(clamp((l1² + l2² - (d/s)²) / (2 l1 l2), -1, -cos(flex_max)))``
    (law of cosines, eq. 9 of the limb solver; the distance is clamped to
    the reach, so θ ∈ [0, flex_max]).  Variables: ``d`` world distance
    base → control, ``s`` the armature object's world scale (uniform);
    l1, l2: segment lengths in metres (armature space).
    """
    # Plain floats: numpy 2 would write np.float64(...) into the expression (repr), which is not a
    # simple expression and would stop the driver on Blender 5.1+.
    k = float(l1 * l1 + l2 * l2)
    c = float(1.0 / (2.0 * l1 * l2))
    hi = float(-math.cos(flex_max))
    return f"pi - acos(max(-1.0, min({hi!r}, ({k!r} - d * d / (s * s)) * {c!r})))"


def _flexion_driver(obj, pb, r: LimbRig):
    """Driver ``rotation_euler[0] = θ(d)`` on the MCH forearm / shin: the IK starts at the answer.

    ``d`` is the distance from the swivel reference bone's head (the limb
    base) to the control's head.  Blender's IK (which stops once an update
    is below 1e-3 rad) then only aims the chain and applies the pole, so the
    result is exact to float precision instead of to the solver tolerance.
    """
    path = f'pose.bones["{pb.name}"].rotation_euler'
    if obj.animation_data is not None:
        for fc in list(obj.animation_data.drivers):
            if fc.data_path == path:
                obj.animation_data.drivers.remove(fc)
    bones = obj.data.bones
    l1 = (bones[r.mid].head_local - bones[r.base].head_local).length
    l2 = (bones[r.end].head_local - bones[r.mid].head_local).length
    fc = pb.driver_add("rotation_euler", 0)
    for m in list(fc.modifiers):
        fc.modifiers.remove(m)
    drv = fc.driver
    drv.type = 'SCRIPTED'
    var = drv.variables.new()
    var.name = "d"
    var.type = 'LOC_DIFF'
    for t, bone in zip(var.targets, (r.ref, r.ctrl)):
        t.id = obj
        t.bone_target = bone
        t.transform_space = 'WORLD_SPACE'
    # world distance / the object's world scale = armature-space distance
    sc = drv.variables.new()
    sc.name = "s"
    sc.type = 'TRANSFORMS'
    sc.targets[0].id = obj
    sc.targets[0].transform_type = 'SCALE_AVG'
    sc.targets[0].transform_space = 'WORLD_SPACE'
    drv.expression = flexion_expression(l1, l2, float(ls.FLEX_MAX[r.index]))
    return fc


def setup_swivel_reference(obj, r: LimbRig):
    """The swivel reference bone ``r.ref``: pose Euler Y = the swivel (driver on
    ``obj["swivel_<limb>"]``), then a Damped Track (Y) to the control ``r.ctrl``.  Its pole child
    then sits in the direction the elbow / knee bends towards (module docstring)."""
    ref = obj.pose.bones[r.ref]
    ref.rotation_mode = 'XYZ'
    ref.rotation_euler = (0.0, 0.0, 0.0)
    ref.location = (0.0, 0.0, 0.0)
    _swivel_driver(obj, ref, r.limb)
    c = _constraint(ref, 'DAMPED_TRACK', "swivel track")
    c.target, c.subtarget, c.track_axis, c.head_tail = obj, r.ctrl, 'TRACK_Y', 0.0
    return c


def setup_ik_chain(obj, r: LimbRig):
    """The two-bone IK chain ``r.upper`` -> ``r.lower`` (both straight along their local Y at
    rest, hinge about local X): the lower bone's hinge in ``[0, FLEX_MAX]`` (Y / Z locked), its
    Euler X pre-set by the flexion driver (:func:`_flexion_driver`, lengths from ``r.base`` /
    ``r.mid`` / ``r.end``), an IK constraint to ``r.ctrl`` with the pole ``r.pole`` at
    :data:`POLE_ANGLE`, no stretch.  Returns the IK constraint."""
    pbs = obj.pose.bones
    lo = pbs[r.lower]
    lo.rotation_mode = 'XYZ'
    lo.rotation_euler = (0.0, 0.0, 0.0)
    _flexion_driver(obj, lo, r)
    lo.lock_ik_x, lo.lock_ik_y, lo.lock_ik_z = False, True, True
    lo.use_ik_limit_x = True
    lo.ik_min_x, lo.ik_max_x = 0.0, float(ls.FLEX_MAX[r.index])
    lo.ik_stretch = 0.0
    pbs[r.upper].ik_stretch = 0.0
    pbs[r.upper].rotation_quaternion = (1.0, 0.0, 0.0, 0.0)
    ik = _constraint(lo, 'IK', "IK")
    ik.target, ik.subtarget = obj, r.ctrl
    ik.pole_target, ik.pole_subtarget = obj, r.pole
    ik.pole_angle = POLE_ANGLE
    ik.chain_count = 2
    ik.use_tail = True
    ik.use_stretch = False
    ik.iterations = IK_ITERATIONS
    return ik


def twist_constraint(obj, pb, name, target, space, from_range, to_range, mix='AFTER'):
    """A Transformation constraint on pose bone ``pb``: the twist (swing-twist about Y) of bone
    ``target`` measured in the space of bone ``space``, ``from_range`` (radians, min, max; values
    outside are clamped) mapped linearly to ``to_range``, applied as a rotation about ``pb``'s own
    Y in its local space (``mix``: 'AFTER' adds it after the bone's rotation, 'REPLACE' replaces
    it).  Used for the forearm pronation and for twist bones' shares."""
    c = _constraint(pb, 'TRANSFORM', name)
    c.target, c.subtarget = obj, target
    c.target_space = 'CUSTOM'
    c.space_object, c.space_subtarget = obj, space
    c.owner_space = 'LOCAL'
    c.map_from, c.map_to = 'ROTATION', 'ROTATION'
    c.from_rotation_mode = 'SWING_TWIST_Y'
    c.map_to_x_from, c.map_to_y_from, c.map_to_z_from = 'X', 'Y', 'Z'
    c.from_min_x_rot = c.from_max_x_rot = 0.0
    c.from_min_z_rot = c.from_max_z_rot = 0.0
    c.from_min_y_rot, c.from_max_y_rot = float(from_range[0]), float(from_range[1])
    c.to_min_y_rot, c.to_max_y_rot = float(to_range[0]), float(to_range[1])
    c.use_motion_extrapolate = False
    c.mix_mode_rot = mix
    return c


def _setup_constraints(obj):
    _clear_rig_constraints(obj)
    obj.pose.ik_solver = 'LEGACY'
    pbs = obj.pose.bones
    for r in LIMB_RIGS:
        for name in (r.ctrl, r.ref, r.pole, r.upper, r.lower, r.base, r.mid, r.end):
            pbs[name].rotation_mode = 'QUATERNION'
        setup_swivel_reference(obj, r)
        setup_ik_chain(obj, r)
        # deform bones follow the chain; the hand / foot takes the control's rotation
        for deform, mch in ((r.base, r.upper), (r.mid, r.lower)):
            pb = pbs[deform]
            pb.rotation_quaternion = (1.0, 0.0, 0.0, 0.0)
            pb.location = (0.0, 0.0, 0.0)
            c = _constraint(pb, 'COPY_TRANSFORMS', "follow IK")
            c.target, c.subtarget = obj, mch
            c.owner_space = c.target_space = 'WORLD'
        if r.is_arm:
            # forearm pronation tau: swing-twist-Y of the hand control in the MCH forearm frame
            lim = ls.TWIST_RANGE[r.index]
            twist_constraint(obj, pbs[r.mid], "pronation", r.ctrl, r.lower, lim, lim, 'AFTER')
        end = pbs[r.end]
        end.rotation_quaternion = (1.0, 0.0, 0.0, 0.0)
        # constrained bones: their own channels do nothing, lock them against accidental keys
        for name in (r.base, r.mid, r.end, r.ref, r.pole, r.upper, r.lower):
            pb = pbs[name]
            pb.lock_location = pb.lock_rotation = pb.lock_scale = (True, True, True)
            pb.lock_rotation_w = True
        c = _constraint(end, 'COPY_ROTATION', "hand rotation" if r.is_arm else "foot rotation")
        c.target, c.subtarget = obj, r.ctrl
        c.owner_space = c.target_space = 'WORLD'
        c.mix_mode = 'REPLACE'
        c.use_x = c.use_y = c.use_z = True


def set_rig_enabled(obj, enabled: bool):
    """Mute (``enabled=False``) or unmute the live rig's constraints on ``obj``.

    Muted, the limb bones play their own keys again (e.g. after assigning
    an FK action back: a solve made without the live rig, or a bake).  Returns the number of
    constraints changed.
    """
    n = 0
    for pb in obj.pose.bones:
        for c in pb.constraints:
            if is_rig_constraint(c) and c.mute == bool(enabled):
                c.mute = not enabled
                n += 1
    return n


def _frames_for(obj, result, frames, scene):
    if frames is not None:
        frames = np.asarray(frames, dtype=np.float64).ravel()
        if frames.shape[0] != result.num_frames:
            raise ValueError(f"{frames.shape[0]} frames for a result of {result.num_frames}")
        return frames
    ad = obj.animation_data
    if ad is not None and ad.action is not None:
        for fc in keying.action_fcurves(ad.action, obj):
            if fc.data_path == f'["{writer.SWIVEL_PROPS[sk.LIMB_NAMES[0]]}"]':
                n = len(fc.keyframe_points)
                if n == result.num_frames:
                    co = np.empty(2 * n, dtype=np.float32)
                    fc.keyframe_points.foreach_get("co", co)
                    return co[0::2].astype(np.float64)
    step = writer.scene_fps(scene) / float(result.fps)
    return 1.0 + np.arange(result.num_frames, dtype=np.float64) * step


def _ensure_solved_properties(obj):
    for limb, name in SOLVED_PROPS.items():
        if name not in obj.keys():
            obj[name] = 0.0
        try:
            obj.id_properties_ui(name).update(
                subtype='ANGLE', description=f"MANIKIN: the solver's swivel of the {limb.replace('_', ' ')} "
                f"(radians), kept for 'Reset Swivel'")
        except (AttributeError, TypeError):
            pass


def live_channels(obj, result: PoseResult):
    """The channels :func:`build_live_rig` keys, as ``(data_path, index, group, values)``.

    Values: quaternions (w, x, y, z) of the FK joints (``Q = Bᵀ R_local B``),
    pelvis location (metres, its rest frame), control locations (metres,
    control rest frame = wrist / ankle rest frame) and rotations
    (``Q = Bᵀ R_world B``), swivel angles (radians, unwrapped).
    """
    heads, rest_mats = arm_mod.rest_matrices(obj)
    fk_j = [sk.J[name] for name in FK_JOINTS]
    quats = arm_mod.pose_bone_quaternions(result.local_rot[:, fk_j], rest_mats[fk_j])
    # world poses of the wrists and ankles only, a chunk at a time (a long take's whole FK,
    # (T, 22, 3, 3), would stay cached on the result)
    ends = [sk.J[r.end] for r in LIMB_RIGS]
    T = result.num_frames
    pos, wrot = np.empty((T, len(ends), 3)), np.empty((T, len(ends), 3, 3))
    for f, p, w in result.fk_chunks():
        pos[f], wrot[f] = p[:, ends], w[:, ends]
    ch = []
    for k, name in enumerate(FK_JOINTS):
        for i in range(4):
            ch.append((f'pose.bones["{name}"].rotation_quaternion', i, name, quats[:, k, i]))
    loc = arm_mod.root_locations(result.root_pos, heads[0], rest_mats[0])
    root = sk.JOINT_NAMES[0]
    for i in range(3):
        ch.append((f'pose.bones["{root}"].location', i, root, loc[:, i]))
    bones = obj.data.bones
    for k, r in enumerate(LIMB_RIGS):
        m = np.array(bones[r.ctrl].matrix_local, dtype=np.float64)
        B = rot.orthonormalize(m[:3, :3])
        Q = np.einsum("ki,tkl,lm->tim", B, wrot[:, k], B)
        q = rot.quat_continuous(rot.matrix_to_quat(Q), axis=0)
        cl = (pos[:, k] - m[:3, 3]) @ B
        for i in range(3):
            ch.append((f'pose.bones["{r.ctrl}"].location', i, CTRL_GROUP, cl[:, i]))
        for i in range(4):
            ch.append((f'pose.bones["{r.ctrl}"].rotation_quaternion', i, CTRL_GROUP, q[:, i]))
    swivel = writer.unwrap_swivel(result.swivel)
    for li, limb in enumerate(sk.LIMB_NAMES):
        ch.append((f'["{writer.SWIVEL_PROPS[limb]}"]', 0, writer.SWIVEL_GROUP, swivel[:, li]))
        ch.append((f'["{SOLVED_PROPS[limb]}"]', 0, SOLVED_GROUP, swivel[:, li]))
    ch.extend(writer.contact_channels(result))
    return ch


def build_live_rig(armature_obj, result: PoseResult, action=None, frames=None, context=None,
                   interpolation: str = 'LINEAR', action_name: str = "MANIKIN_live"):
    """Convert a solved MANIKIN armature to the live swivel rig and key ``result`` on it.

    armature_obj: armature made by :func:`.armature.create_armature` (the
    22 joint bones; the one :func:`.writer.write_result` made, keyed or not).
    result: the :class:`PoseResult` to key.  action: the action to write
    into; None (default) creates a NEW action ``action_name[.NNN]`` -- the
    armature's current action, if any, is never modified (it is given a fake user so it stays
    in the file; assign it back, with :func:`set_rig_enabled` off, to
    return to its FK keys; on an error it is assigned again, with its slot).  frames: scene
    frame of each result frame; None: the frames of the current action's
    swivel keys when it has one key per result frame, else
    ``1 + k * scene_fps / result.fps``.

    Adds the bones, constraints and drivers described in the module
    docstring (idempotent: running it again re-places them), resets the
    pose channels of the constrained limb bones, and keys (bulk, via
    :mod:`.keying`) the channels of :func:`live_channels`.  Returns the action.
    """
    context = context or bpy.context
    obj = armature_obj
    if obj is None or obj.type != 'ARMATURE':
        raise TypeError("build_live_rig needs an armature object")
    frames = _frames_for(obj, result, frames, context.scene)
    _create_bones(obj, context)
    writer.ensure_swivel_properties(obj)
    writer.ensure_contact_properties(obj)
    _ensure_solved_properties(obj)
    _setup_constraints(obj)
    created = action is None
    current = obj.animation_data.action if obj.animation_data else None
    if not created and action == current and not action.get(PROP_LIVE):
        raise ValueError(f"action {action.name!r} is the armature's current (solve / user) action; "
                         f"build_live_rig never overwrites it -- pass action=None for a new one")
    if created:
        action = keying.new_action(action_name)
        action[PROP_LIVE] = 1
    before = keying.keep_active_action(obj)
    try:
        keying.assign_action(obj, action)
        fcs = keying.key_channels(action, obj, frames, live_channels(obj, result), interpolation)
    except BaseException:
        keying.restore_assignment(obj, before)
        if created:
            bpy.data.actions.remove(action)
        raise
    for fc in fcs:
        if fc.data_path.startswith('["swivel_solved_'):
            fc.lock = True
            fc.hide = True
    obj[PROP_LIVE] = 1
    obj.update_tag()
    return action


# --------------------------------------------------------------------------
# reading a solved FK action back (for the "Make Live" operator)
def result_from_fk_action(obj, fps: float, action=None):
    """A :class:`PoseResult` and its scene frames from a solve's FK keys on ``obj``.

    Reads the keys :func:`.writer.write_result` writes (every joint's
    ``rotation_quaternion``, pelvis ``location``, swivel properties) from
    ``action`` (default: the assigned one), evaluated at the key frames of
    the pelvis rotation.  Missing swivel curves are computed from the joint
    positions.  Raises ``ValueError`` when the action has no MANIKIN keys, or is a live rig's
    (:func:`build_live_rig`: its arms and legs follow the controls, not keys of their own).
    """
    action = action or (obj.animation_data.action if obj.animation_data else None)
    if action is None:
        raise ValueError(f"{obj.name!r} has no action to read")
    if action.get(PROP_LIVE):
        raise ValueError(f"action {action.name!r} is a live rig's (its arms and legs follow the hand and foot "
                         f"controls, they have no keys of their own): {obj.name!r} is live already (Make Live Rig "
                         f"reads the keys of a plain FK solve's action)")
    fcs = {(fc.data_path, fc.array_index): fc for fc in keying.action_fcurves(action, obj)}
    key = ('pose.bones["pelvis"].rotation_quaternion', 0)
    if key not in fcs or not len(fcs[key].keyframe_points):
        raise ValueError(f"action {action.name!r} has no MANIKIN pelvis keys")
    kp = fcs[key].keyframe_points
    co = np.empty(2 * len(kp), dtype=np.float32)
    kp.foreach_get("co", co)
    frames = co[0::2].astype(np.float64)

    def curve(path, index, default):
        fc = fcs.get((path, index))
        if fc is None:
            return np.full(len(frames), default)
        return np.array([fc.evaluate(f) for f in frames])

    heads, rest_mats = arm_mod.rest_matrices(obj)
    q = np.empty((len(frames), sk.NUM_JOINTS, 4))
    for j, name in enumerate(sk.JOINT_NAMES):
        for i in range(4):
            q[:, j, i] = curve(f'pose.bones["{name}"].rotation_quaternion', i, 1.0 if i == 0 else 0.0)
    Q = rot.quat_to_matrix(rot.normalize(q))
    local = np.einsum("jik,tjkl,jml->tjim", rest_mats, Q, rest_mats)
    loc = np.stack([curve('pose.bones["pelvis"].location', i, 0.0) for i in range(3)], -1)
    root = heads[0] + loc @ rest_mats[0].T
    body = _body_from_object(obj)
    res = PoseResult(fps=float(fps), body=body, local_rot=local, root_pos=root,
                     swivel=np.zeros((len(frames), 4)))
    pos, wrot = res.fk()
    sw = ls.swivel_from_positions(pos[:, ls.LIMB_BASE], pos[:, ls.LIMB_MID], pos[:, ls.LIMB_END],
                                  wrot[:, ls.LIMB_PARENT], base_rot=wrot[:, ls.LIMB_BASE])
    for li, limb in enumerate(sk.LIMB_NAMES):
        fc = fcs.get((f'["{writer.SWIVEL_PROPS[limb]}"]', 0))
        if fc is not None and len(fc.keyframe_points):
            keyed = np.array([fc.evaluate(f) for f in frames])
            # keep the keyed (unwrapped) values when they agree with the pose
            if np.max(np.abs(np.angle(np.exp(1j * (keyed - sw[:, li]))))) < 1e-3:
                sw[:, li] = keyed
    res.swivel = sw
    return res, frames


# --------------------------------------------------------------------------
# baking
def evaluated_pose_matrices(obj_eval, order):
    """``(len(order), 4, 4)`` armature-space pose matrices of the evaluated object (bulk read).

    order: indices into ``obj_eval.pose.bones``.
    """
    pbs = obj_eval.pose.bones
    buf = np.empty(len(pbs) * 16, dtype=np.float32)
    pbs.foreach_get("matrix", buf)
    # RNA matrices are stored column-major
    return np.swapaxes(buf.reshape(len(pbs), 4, 4), -1, -2)[order].astype(np.float64)


def check_pose_evaluated(obj):
    """``ValueError`` when the armature ``obj`` is in Edit Mode: Blender does not evaluate its pose
    there (its pose bones read the rest pose on every frame), so a bake or retarget sampling it
    would key the rest pose."""
    if obj.mode == 'EDIT':
        raise ValueError(f"armature {obj.name!r} is in Edit Mode, where Blender does not evaluate its "
                         f"pose (every frame would read as the rest pose): go to Object or Pose Mode first")


def sample_pose_matrices(obj, names, frames, context=None):
    """``(len(frames), len(names), 4, 4)`` armature-space pose matrices of bones ``names`` of
    ``obj`` as Blender evaluates them (constraints, drivers, IK) on each scene frame of
    ``frames`` (integers; ``scene.frame_set``, the current frame restored afterwards).
    ``ValueError`` when ``obj`` is in Edit Mode (:func:`check_pose_evaluated`)."""
    check_pose_evaluated(obj)
    context = context or bpy.context
    scene = context.scene
    order = [obj.pose.bones.find(n) for n in names]
    M = np.empty((len(frames), len(names), 4, 4))
    prev = scene.frame_current, scene.frame_subframe
    try:
        for t, f in enumerate(frames):
            scene.frame_set(int(f))
            M[t] = evaluated_pose_matrices(obj.evaluated_get(context.evaluated_depsgraph_get()), order)
    finally:
        scene.frame_set(prev[0], subframe=prev[1])
    return M


def pose_basis(rest, rest_parent, pose, pose_parent, has_parent):
    """Pose-bone basis matrices (what the bones' own channels must hold) reproducing evaluated
    armature-space ``pose`` matrices, Blender's default inheritance:
    ``basis = (rest_p⁻¹ rest_k)⁻¹ (pose_p⁻¹ pose_k)``; bones without a parent ``rest_k⁻¹ pose_k``.

    rest, rest_parent: ``(B, 4, 4)`` ``bone.matrix_local`` of each bone and of its parent;
    pose, pose_parent: ``(T, B, 4, 4)``; has_parent: ``(B,)`` bool.  Returns ``(T, B, 4, 4)``.
    """
    eye = np.eye(4)
    has_parent = np.asarray(has_parent, dtype=bool)
    rest_p = np.where(has_parent[:, None, None], rest_parent, eye)
    rel_rest = np.linalg.inv(rest_p) @ rest
    pose_p = np.where(has_parent[None, :, None, None], pose_parent, eye)
    return np.linalg.inv(rel_rest)[None] @ (np.linalg.inv(pose_p) @ pose)


def check_frame_range(frame_start, frame_end):
    """``(int start, int end)``; ValueError when the range is empty."""
    frame_start, frame_end = int(frame_start), int(frame_end)
    if frame_end < frame_start:
        raise ValueError(f"frame range {frame_start}..{frame_end} is empty")
    return frame_start, frame_end


def fk_key_channels(obj, names, parents, frames, context=None, modes=None):
    """Keying channels (:func:`.keying.key_channels`) that reproduce, as plain FK, the pose Blender
    evaluates for bones ``names`` of ``obj`` on the scene frames ``frames``.

    parents: per bone, the bone its keys are relative to (its parent in the armature the keys go
    to; None: none).  ``rotation_quaternion`` (w, x, y, z, sign-continuous) for every bone, or
    with ``modes`` (bone name → rotation mode) in each bone's mode
    (:func:`.keying.rotation_channels`); ``location`` (bone rest frame) for bones without a
    parent or moved off their rest offset."""
    bones = obj.data.bones
    sampled = list(dict.fromkeys(list(names) + [p for p in parents if p is not None]))
    idx = {n: k for k, n in enumerate(sampled)}
    M = sample_pose_matrices(obj, sampled, frames, context)
    rest = np.array([np.array(bones[n].matrix_local, dtype=np.float64) for n in sampled])
    own = [idx[n] for n in names]
    par = [idx[p] if p is not None else idx[n] for n, p in zip(names, parents)]
    has_parent = np.array([p is not None for p in parents])
    basis = pose_basis(rest[own], rest[par], M[:, own], M[:, par], has_parent)
    q = rot.quat_continuous(rot.matrix_to_quat(rot.orthonormalize(basis[..., :3, :3])), axis=0)
    ch = keying.rotation_channels(names, q, [(modes or {}).get(n, 'QUATERNION') for n in names])
    for k, n in enumerate(names):
        if parents[k] is None or np.max(np.abs(basis[:, k, :3, 3])) > 1e-6:
            for i in range(3):
                ch.append((f'pose.bones["{n}"].location', i, n, basis[:, k, i, 3]))
    return ch


def deform_bone_names(obj):
    """Bones a bake keeps: deforming bones that are not part of the live rig, parents first."""
    rig = set(RIG_BONES)
    return [b.name for b in obj.data.bones if b.use_deform and b.name not in rig]


def bake_live_rig(armature_obj, frame_start: int, frame_end: int, name: str | None = None,
                  context=None, interpolation: str = 'LINEAR'):
    """Bake the evaluated pose of ``armature_obj`` into plain FK keys on a NEW armature object.

    Every integer scene frame in ``[frame_start, frame_end]`` is evaluated
    (``scene.frame_set``; the current frame is restored afterwards) and, for
    every deforming bone that is not a live-rig bone, its pose
    ``rotation_quaternion`` (w, x, y, z, sign-continuous) is keyed, plus
    ``location`` (metres, bone rest frame) for bones without a parent.
    The new object (``<name>_baked`` by default) has a copy of the armature
    data reduced to those bones, no constraints, drivers or custom
    properties other than the MANIKIN body marks, the source's world
    transform, and a NEW action (bulk-written with :mod:`.keying`), and a copy of the
    source's mannequin (:mod:`.body_mesh`) when it has one.  It is
    linked to the source's collections.  Returns the new object.
    """
    context = context or bpy.context
    src = armature_obj
    frame_start, frame_end = check_frame_range(frame_start, frame_end)
    names = deform_bone_names(src)
    if not names:
        raise ValueError(f"{src.name!r} has no deforming bones to bake")
    bones = src.data.bones
    parent = [bones[n].parent.name if bones[n].parent is not None else None for n in names]
    # the nearest kept ancestor (bones are reduced to `names`)
    keep = set(names)
    for k, n in enumerate(names):
        p = bones[n].parent
        while p is not None and p.name not in keep:
            p = p.parent
        parent[k] = p.name if p is not None else None
    frames = np.arange(frame_start, frame_end + 1)
    ch = fk_key_channels(src, names, parent, frames, context)
    new = _plain_copy(src, names, name or f"{src.name}_baked", context)
    try:
        action = keying.new_action(f"{new.name}_action")
        keying.assign_action(new, action)
        keying.key_channels(action, new, frames.astype(np.float64), ch, interpolation)
        from . import body_mesh
        body_mesh.copy_body_mesh(src, new, context)
    except BaseException:
        data = new.data
        bpy.data.objects.remove(new)
        bpy.data.armatures.remove(data)
        raise
    return new


def _plain_copy(src, names, name, context):
    """New armature object with a copy of ``src``'s bones reduced to ``names`` (in object mode)."""
    data = src.data.copy()
    data.name = name
    obj = bpy.data.objects.new(name, data)
    colls = list(src.users_collection) or [context.scene.collection]
    for c in colls:
        c.objects.link(obj)
    obj.matrix_world = src.matrix_world.copy()
    for key in (arm_mod.PROP_MARK, arm_mod.PROP_BODY):
        if key in src.keys():
            obj[key] = src[key]
    keep = set(names)
    with _edit_mode(obj, context) as eb:
        for b in list(eb):
            if b.name not in keep:
                eb.remove(b)
    if "collections" in data.bl_rna.properties:
        for c in list(data.collections):
            if c.name in (COLL_CTRL, COLL_MCH):
                data.collections.remove(c)
    for pb in obj.pose.bones:
        pb.rotation_mode = 'QUATERNION'
    return obj


# --------------------------------------------------------------------------
# swivel curve tools (used by the operators)
def swivel_fcurve(obj, limb: str, solved: bool = False, create: bool = False):
    """The F-curve of ``["swivel_<limb>"]`` (or the solved copy) in ``obj``'s action, or None.

    Slotted actions (Blender 4.4+): the curve of the slot ``obj`` is animated by; ``ValueError``
    when it has none assigned (an action assigned whose slots other objects use), as that
    object's keys would animate nothing, and a slot found by ``obj``'s name may be another
    object's (a linked duplicate's).  ``ValueError`` too when the action is linked from a library
    (an armature linked into a shot file): its keys would change in memory and be lost on save."""
    ad = obj.animation_data
    if ad is None or ad.action is None:
        return None
    if keying.is_slotted(ad.action) and getattr(ad, "action_slot", None) is None:
        raise ValueError(f"{obj.name!r} has action {ad.action.name!r} but no slot of it assigned, so its swivel "
                         f"keys would animate nothing (or another object using that action): choose its slot "
                         f"under the action (Object properties > Animation, or the Action editor)")
    if not ad.action.is_editable:
        raise ValueError(f"{obj.name!r} is animated by action {ad.action.name!r}, linked from "
                         f"{plain.shown(ad.action.library.filepath if ad.action.library else 'a library')}: its swivel "
                         f"keys cannot be edited in this file (an edit would not be saved); edit them in that "
                         f"file, or make the action local")
    path = f'["{(SOLVED_PROPS if solved else writer.SWIVEL_PROPS)[limb]}"]'
    for fc in keying.action_fcurves(ad.action, obj):
        if fc.data_path == path and fc.array_index == 0:
            return fc
    if create:
        return keying.ensure_fcurve(ad.action, path, 0, SOLVED_GROUP if solved else writer.SWIVEL_GROUP, obj)
    return None


def read_keys(fcurve):
    """``(frames, values)`` float64 arrays of ``fcurve``'s keys (bulk)."""
    n = len(fcurve.keyframe_points)
    co = np.empty(2 * n, dtype=np.float32)
    if n:
        fcurve.keyframe_points.foreach_get("co", co)
    return co[0::2].astype(np.float64), co[1::2].astype(np.float64)


def _interpolation_of(fcurve):
    kp = fcurve.keyframe_points
    return kp[0].interpolation if len(kp) else 'LINEAR'


def smooth_values(frames, values, sigma: float, method: str = 'GAUSSIAN', mask=None):
    """Smooth key ``values`` (radians) over time; only keys where ``mask`` is True change.

    frames: ``(n,)`` key frames; sigma: Gaussian standard deviation in frames
    ('GAUSSIAN', window ±3σ) or the half width of a box ('BOX', window
    ±sigma).  Values are unwrapped first (no jumps across ±π) and the
    weights are normalised over the keys present (ends and gaps are
    handled).  Returns a new ``(n,)`` array.
    """
    frames = np.asarray(frames, np.float64)
    if np.any(np.diff(frames) < 0):
        raise ValueError("key frames must be sorted")
    v = np.unwrap(np.asarray(values, np.float64))
    shift = np.asarray(values, np.float64) - v          # restore the original 2π branch
    mask = np.ones(len(v), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    out = v.copy()
    if sigma <= 0 or len(v) < 2:
        return np.asarray(values, np.float64).copy()
    reach = (sigma if method == 'BOX' else 3.0 * sigma) + 1e-9
    rows = np.nonzero(mask)[0]
    sm = np.empty(len(rows))
    for a in range(0, len(rows), 1024):          # banded: memory ~ 1024 x window, not n x n
        r = rows[a:a + 1024]
        lo = np.searchsorted(frames, frames[r[0]] - reach, 'left')
        hi = np.searchsorted(frames, frames[r[-1]] + reach, 'right')
        d = frames[r, None] - frames[None, lo:hi]
        if method == 'BOX':
            w = (np.abs(d) <= reach).astype(np.float64)
        else:
            w = np.exp(-0.5 * (d / sigma) ** 2) * (np.abs(d) <= reach)
        sm[a:a + len(r)] = (w @ v[lo:hi]) / np.sum(w, axis=1)
    out[rows] = sm
    return out + shift


def smooth_swivel(obj, limbs, frame_start, frame_end, sigma: float, method: str = 'GAUSSIAN'):
    """Smooth the swivel keys of ``limbs`` with frames in ``[frame_start, frame_end]`` (bulk; the
    keys keep their interpolation and handles, keys outside the range are not touched).

    Returns the number of keys changed.
    """
    count = 0
    for limb in limbs:
        fc = swivel_fcurve(obj, limb)
        if fc is None or len(fc.keyframe_points) < 2:
            continue
        f, v = read_keys(fc)
        mask = (f >= frame_start - 1e-6) & (f <= frame_end + 1e-6)
        if not mask.any():
            continue
        keying.update_keys(fc, f[mask], smooth_values(f, v, sigma, method, mask)[mask])
        count += int(mask.sum())
    return count


def reset_swivel(obj, limbs, frame_start=None, frame_end=None):
    """Copy the solved swivel (``["swivel_solved_<limb>"]`` keys) back onto the swivel keys.

    Keys of the swivel curve inside ``[frame_start, frame_end]`` (None: all)
    are replaced by the solved keys in that range; keys outside are kept as they are (values,
    interpolation, handles).  Returns the number of limbs reset.
    """
    done = 0
    for limb in limbs:
        solved = swivel_fcurve(obj, limb, solved=True)
        if solved is None or not len(solved.keyframe_points):
            continue
        fs, vs = read_keys(solved)
        fc = swivel_fcurve(obj, limb, create=True)
        f, v = read_keys(fc)
        lo = -np.inf if frame_start is None else frame_start - 1e-6
        hi = np.inf if frame_end is None else frame_end + 1e-6
        take = (fs >= lo) & (fs <= hi)
        keying.update_keys(fc, fs[take], vs[take], drop=(f >= lo) & (f <= hi),
                           interpolation=_interpolation_of(solved))
        done += 1
    return done


def action_frame(obj, frame: float) -> float:
    """The frame of ``obj``'s action shown at scene ``frame``: the same frame, except in NLA tweak
    mode, where the edited strip's action is mapped (the strip's start, scale and repeat) as
    Blender's own keying maps it."""
    ad = obj.animation_data
    if ad is not None and ad.use_tweak_mode and hasattr(ad, "nla_tweak_strip_time_to_scene"):
        return float(ad.nla_tweak_strip_time_to_scene(float(frame), invert=True))
    return frame


def action_frame_range(obj, frame_start, frame_end):
    """:func:`action_frame` of a scene frame range (None ends kept), in increasing order."""
    if frame_start is None or frame_end is None:
        return frame_start, frame_end
    a, b = action_frame(obj, frame_start), action_frame(obj, frame_end)
    return min(a, b), max(a, b)


def key_swivel(obj, limbs, frame: float, values=None, context=None):
    """Key the swivel of ``limbs`` at ``frame`` of the action (the scene's frame, except in NLA tweak
    mode: :func:`action_frame`; the curve's other keys are not touched).

    values: limb -> radians; default each property's current value (what the
    slider shows, including unkeyed edits).  The key makes Blender *show* that value at the
    scene's current frame: when the action is blended through the NLA (a strip in tweak mode
    over other tracks, Add / Combine / Multiply blending, influence below 1, blend in / out) the
    keyed value is remapped through the blend as Blender's own keying does
    (:func:`.keying.nla_remap_values`; ``ValueError`` where the strip has no effect).  An
    existing key at ``frame`` takes the value (keeping its interpolation and handles).
    Returns the number of keys written.
    """
    ad = obj.animation_data
    if ad is None or ad.action is None:
        ad = keying.assign_action(obj, keying.new_action("MANIKIN_live"))
    todo = [limb for limb in limbs if writer.SWIVEL_PROPS[limb] in obj.keys()]
    shown = [float(obj[writer.SWIVEL_PROPS[limb]] if values is None or limb not in values else values[limb])
             for limb in todo]
    fcs = [swivel_fcurve(obj, limb, create=True) for limb in todo]
    if not fcs:
        return 0
    # the remap re-evaluates the frame: other limbs' unkeyed slider edits are put back afterwards
    others = {p: float(obj[p]) for limb, p in writer.SWIVEL_PROPS.items() if limb not in todo and p in obj.keys()}
    keyed = keying.nla_remap_values(obj, fcs, shown, context)
    for fc, value in zip(fcs, keyed):
        # Blender's keying: Ctrl+Z then gives back the slider's unkeyed value (key_as_blender)
        if not keying.key_as_blender(obj, fc, frame, value):
            keying.update_keys(fc, [frame], [value])
    if keying.nla_blends(obj):
        scene = (context or bpy.context).scene
        scene.frame_set(scene.frame_current, subframe=scene.frame_subframe)
        for p, v in others.items():
            obj[p] = v
    return len(fcs)
