"""Bulk F-curve keying on both Blender action APIs.

* Blender 4.4+ / 5.x: *slotted* actions.  F-curves live in a channelbag,
  ``action.layers[0].strips[0].channelbag(slot)``, for the slot of the
  animated ID (``Action.fcurves`` was removed in 5.0).
* Blender 4.2-4.3: ``action.fcurves``.

The API is chosen by feature detection (:func:`is_slotted`), never by version
number; 4.4-4.5 have both APIs and take the slotted path; 4.3's experimental
layered actions (``slots.new(for_id)``) take the legacy path.

Keys are always written in bulk: ``fcurve.keyframe_points.add(n)``, then
``foreach_set('co', ...)`` and ``foreach_set('interpolation', ...)``, then
``fcurve.update()``.  The one exception is a single key at the current frame
(:func:`key_as_blender`, *Key Swivel*): it goes through ``keyframe_insert``, as
Blender's own Insert Keyframe does, so that Ctrl+Z keeps the slider's unkeyed value.

Frames are scene frames (float, ``co[0]``); values are in the RNA property's
units (radians for rotations and the swivel angles, metres for locations).
"""
from __future__ import annotations

import numpy as np

import bpy

from ..core import rotations as rot


def is_slotted(action) -> bool:
    """True when ``action`` is written through the slotted (layers / channelbags) API.

    5.x (no ``action.fcurves``): always.  4.4-4.5 (both APIs): yes, detected
    by ``ActionSlots.new`` taking ``id_type`` (4.3's experimental layered
    actions had ``slots.new(for_id)`` and must use ``action.fcurves``).
    4.2-4.3 without usable slots: no.
    """
    if not (hasattr(action, "slots") and hasattr(action, "layers")):
        return False
    if not hasattr(action, "fcurves"):
        return True
    try:
        params = action.slots.bl_rna.functions["new"].parameters
        return "id_type" in params.keys()
    except (AttributeError, KeyError):
        return False


def new_action(name: str):
    """A NEW action with a unique name derived from ``name`` (never an existing one).

    ``use_fake_user`` is set so that an earlier solve that is no longer
    assigned survives saving the file.
    """
    action = bpy.data.actions.new(name)
    action.use_fake_user = True
    return action


def find_slot(action, id_owner):
    """The slot of ``action`` for ``id_owner`` or None (slotted API only; creates nothing).

    The slot assigned to ``id_owner`` when ``action`` is its action, else the
    slot whose identifier is the ID's type code + name (e.g. ``"OBbody"``).
    """
    ad = getattr(id_owner, "animation_data", None)
    if ad is not None and ad.action == action and getattr(ad, "action_slot", None) is not None:
        return ad.action_slot
    id_type = getattr(id_owner, "id_type", "OBJECT")
    ident = _id_type_prefix(action, id_type) + id_owner.name
    for slot in action.slots:
        if slot.identifier == ident:
            return slot
    return None


def ensure_slot(action, id_owner):
    """:func:`find_slot`, creating a slot for ``id_owner`` when there is none."""
    slot = find_slot(action, id_owner)
    if slot is None:
        slot = action.slots.new(id_type=getattr(id_owner, "id_type", "OBJECT"), name=id_owner.name)
    return slot


def _id_type_prefix(action, id_type):
    # identifiers are the two-letter ID code + name ("OBbody"); derive the code
    # from an existing slot when possible, else the known code for objects
    for slot in action.slots:
        if getattr(slot, "target_id_type", None) == id_type:
            return slot.identifier[:2]
    return {"OBJECT": "OB", "ARMATURE": "AR", "KEY": "KE", "MATERIAL": "MA"}.get(id_type, "OB")


def ensure_channelbag(action, slot):
    """The channelbag for ``slot`` in the action's first layer / keyframe strip (created if needed)."""
    try:
        from bpy_extras.anim_utils import action_ensure_channelbag_for_slot
    except ImportError:          # 4.4 without the helper: same steps by hand
        action_ensure_channelbag_for_slot = None
    if action_ensure_channelbag_for_slot is not None:
        return action_ensure_channelbag_for_slot(action, slot)
    layer = action.layers[0] if len(action.layers) else action.layers.new("Layer")
    strip = layer.strips[0] if len(layer.strips) else layer.strips.new(type='KEYFRAME')
    return strip.channelbag(slot, ensure=True)


def assign_action(id_owner, action, slot=None):
    """Make ``action`` the active action of ``id_owner`` (and, slotted, assign its slot: ``slot``
    when given, e.g. the one it had before, else :func:`ensure_slot`'s)."""
    ad = id_owner.animation_data or id_owner.animation_data_create()
    ad.action = action
    if is_slotted(action):
        if slot is None or all(s != slot for s in action.slots):
            slot = ensure_slot(action, id_owner)
        if ad.action_slot != slot:
            ad.action_slot = slot
    return ad


def active_assignment(id_owner):
    """``(action, slot, use_fake_user)`` of ``id_owner``'s active action as it is now (``slot``
    None before Blender 4.4 or with no slot assigned; all None without an action): what
    :func:`keep_active_action` protects and :func:`restore_assignment` puts back."""
    ad = getattr(id_owner, "animation_data", None)
    action = ad.action if ad is not None else None
    if action is None:
        return (None, None, None)
    return (action, getattr(ad, "action_slot", None), bool(action.use_fake_user))


def keep_active_action(id_owner):
    """Before a new action replaces ``id_owner``'s active one: give the active action a fake user
    so that, no longer assigned, it is still in the file after saving (an animator's own action,
    made in the Action editor, has none: it would be dropped on save).  Returns
    :func:`active_assignment` as it was, for :func:`restore_assignment`."""
    before = active_assignment(id_owner)
    if before[0] is not None:
        before[0].use_fake_user = True
    return before


def restore_assignment(id_owner, before):
    """Undo :func:`keep_active_action` and any action assigned since: ``id_owner``'s active action,
    its slot and the action's fake user as in ``before`` (:func:`active_assignment`)."""
    action, slot, fake = before
    ad = getattr(id_owner, "animation_data", None)
    if action is None:
        if ad is not None:
            ad.action = None
        return
    assign_action(id_owner, action, slot)
    action.use_fake_user = fake


def _group(groups, name):
    if not name:
        return None
    g = groups.get(name) if hasattr(groups, "get") else None
    if g is None:
        for cand in groups:
            if cand.name == name:
                g = cand
                break
    return g if g is not None else groups.new(name)


def ensure_fcurve(action, data_path: str, index: int = 0, group: str = "", id_owner=None):
    """The F-curve ``(data_path, index)`` of ``action`` for ``id_owner``, created if missing.

    Slotted API: uses (creating if needed) ``id_owner``'s slot and its
    channelbag; ``id_owner`` is required.  Legacy API: ``action.fcurves``.
    ``group`` names the channel group (e.g. the bone name); empty for none.
    """
    if is_slotted(action):
        if id_owner is None:
            raise ValueError("ensure_fcurve on a slotted action needs the animated ID (id_owner)")
        bag = ensure_channelbag(action, ensure_slot(action, id_owner))
        fcurves, groups = bag.fcurves, bag.groups
        fc = fcurves.find(data_path, index=index)
        if fc is None:
            fc = fcurves.new(data_path, index=index)
        g = _group(groups, group)
        if g is not None and fc.group != g:
            fc.group = g
        return fc
    fcurves = action.fcurves
    fc = fcurves.find(data_path, index=index)
    if fc is None:
        fc = fcurves.new(data_path, index=index, action_group=group) if group else \
            fcurves.new(data_path, index=index)
    return fc


def _interp_value(name):
    items = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items
    return items[name].value


def set_keys(fcurve, frames, values, interpolation: str = 'LINEAR'):
    """Replace ``fcurve``'s keys with ``(frames[k], values[k])`` in bulk.

    frames, values: ``(n,)`` array-likes (frames in scene frames).  Existing
    keys are removed first.  ``interpolation`` is any ``Keyframe.interpolation``
    identifier.  Returns ``fcurve``.
    """
    frames = np.asarray(frames, dtype=np.float32).ravel()
    values = np.asarray(values, dtype=np.float32).ravel()
    if frames.shape != values.shape:
        raise ValueError(f"frames {frames.shape} and values {values.shape} differ")
    kp = fcurve.keyframe_points
    if len(kp):
        kp.clear()
    n = frames.shape[0]
    if n == 0:
        return fcurve
    kp.add(n)
    co = np.empty((n, 2), dtype=np.float32)
    co[:, 0] = frames
    co[:, 1] = values
    kp.foreach_set("co", co.ravel())
    kp.foreach_set("interpolation", np.full(n, _interp_value(interpolation), dtype=np.int32))
    fcurve.update()
    return fcurve


#: per-key attributes :func:`update_keys` carries over (enums read and written as their values)
_KEY_ATTRS = (("interpolation", np.int32), ("handle_left_type", np.int32), ("handle_right_type", np.int32),
              ("type", np.int32), ("easing", np.int32), ("back", np.float32), ("amplitude", np.float32),
              ("period", np.float32), ("select_control_point", bool), ("select_left_handle", bool),
              ("select_right_handle", bool))


def update_keys(fcurve, frames, values, drop=None, interpolation: str | None = None):
    """Write keys ``(frames[k], values[k])`` into ``fcurve`` in bulk, keeping every other key as
    the animator left it (interpolation, handles and their types, key type, easing, selection).

    A key already at one of ``frames`` (within 1e-4) gets the new value and keeps its attributes,
    its handles moved with it; ``drop``: ``(len(keyframe_points),)`` bool, existing keys to
    remove first.  New keys take ``interpolation`` (None: that of the key before them, else of
    the first key, else ``'LINEAR'``).  Returns ``fcurve``."""
    kp = fcurve.keyframe_points
    n = len(kp)
    nf = np.asarray(frames, dtype=np.float64).ravel()
    nv = np.asarray(values, dtype=np.float64).ravel()
    if nf.shape != nv.shape:
        raise ValueError(f"frames {nf.shape} and values {nv.shape} differ")
    old = {name: np.empty(n, dt) for name, dt in _KEY_ATTRS}
    co, hl, hr = np.empty(2 * n, np.float32), np.empty(2 * n, np.float32), np.empty(2 * n, np.float32)
    if n:
        for name, buf in old.items():
            kp.foreach_get(name, buf)
        kp.foreach_get("co", co)
        kp.foreach_get("handle_left", hl)
        kp.foreach_get("handle_right", hr)
    co, hl, hr = co.reshape(n, 2).astype(np.float64), hl.reshape(n, 2), hr.reshape(n, 2)
    keep = np.ones(n, bool) if drop is None else ~np.asarray(drop, bool).ravel()
    kept = np.nonzero(keep)[0]
    kept = kept[np.argsort(co[kept, 0], kind="stable")]
    # the kept key at each new frame, if any
    match = np.full(len(nf), -1)
    if len(kept):
        pos = np.clip(np.searchsorted(co[kept, 0], nf), 0, len(kept) - 1)
        for d in (pos, np.maximum(pos - 1, 0)):
            ok = (match < 0) & (np.abs(co[kept[d], 0] - nf) < 1e-4)
            match[ok] = kept[d][ok]
    unmatched = np.setdiff1d(kept, match[match >= 0])
    rows = np.concatenate([unmatched, match[match >= 0]]).astype(int)   # old keys written back
    m = len(rows) + int(np.sum(match < 0))
    # new keys' interpolation
    items = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items
    if interpolation is not None:
        new_interp = np.full(int(np.sum(match < 0)), items[interpolation].value, np.int32)
    else:
        fresh = nf[match < 0]
        if len(kept):
            before = np.clip(np.searchsorted(co[kept, 0], fresh, side="right") - 1, 0, len(kept) - 1)
            new_interp = old["interpolation"][kept[before]]
        else:
            new_interp = np.full(len(fresh), items['LINEAR'].value, np.int32)
    if n:
        kp.clear()
    if m == 0:
        fcurve.update()
        return fcurve
    kp.add(m)
    out = {}
    for name, dt in _KEY_ATTRS:
        buf = np.empty(m, dt)
        kp.foreach_get(name, buf)                # the defaults of a new key
        buf[:len(rows)] = old[name][rows]
        out[name] = buf
    out["interpolation"][len(rows):] = new_interp
    oco = np.empty((m, 2))
    ohl, ohr = np.empty((m, 2)), np.empty((m, 2))
    oco[:len(rows)] = co[rows]
    ohl[:len(rows)], ohr[:len(rows)] = hl[rows], hr[rows]
    # matched keys: the new value, handles moved with it
    j = np.arange(len(unmatched), len(rows))
    dv = nv[match >= 0] - co[match[match >= 0], 1]
    oco[j, 1] = nv[match >= 0]
    ohl[j, 1] += dv
    ohr[j, 1] += dv
    # new keys
    fresh = np.stack([nf[match < 0], nv[match < 0]], -1)
    oco[len(rows):] = ohl[len(rows):] = ohr[len(rows):] = fresh
    order = np.argsort(oco[:, 0], kind="stable")
    for name, buf in out.items():
        kp.foreach_set(name, buf[order])
    kp.foreach_set("co", oco[order].astype(np.float32).ravel())
    kp.foreach_set("handle_left", ohl[order].astype(np.float32).ravel())
    kp.foreach_set("handle_right", ohr[order].astype(np.float32).ravel())
    fcurve.update()
    return fcurve



def _restore_keys(kp, n, old, co, hl, hr):
    """Put back ``n`` keys of ``kp`` (keyframe_points): attributes ``old`` (:data:`_KEY_ATTRS`),
    flat ``co`` / handles ``(2n,)`` float32, as read before Blender's keying."""
    kp.clear()
    kp.add(n)
    for name, buf in old.items():
        kp.foreach_set(name, buf)
    kp.foreach_set("co", co)
    kp.foreach_set("handle_left", hl)
    kp.foreach_set("handle_right", hr)


def key_as_blender(id_owner, fcurve, frame: float, value: float) -> bool:
    """Key ``value`` at ``frame`` (action frames) of ``fcurve``, a curve of ``id_owner``'s
    assigned action (and slot), through Blender's own keying (``id_owner.keyframe_insert``), so
    that Ctrl+Z of the operator doing it gives back the animated properties' unkeyed edits (a
    slider moved but not keyed before the key was made shows its moved value again, as after
    Blender's Insert Keyframe), and another slider's unkeyed edit is not overwritten either.

    Why: ``keyframe_points.add`` / ``insert`` / ``clear``, ``FCurve.update`` and
    ``handles_recalc`` tag the action for a flushed animation update, which the undo system
    replays after Ctrl+Z, so the object's animation is evaluated again and the curve's value
    overwrites the unkeyed edit held in the undo step; Blender's keying tags it without the
    flush.  The key ends as :func:`update_keys` would leave it: an existing key at ``frame``
    (within 1e-4) takes the value and keeps its attributes (interpolation, handle types, key
    type, easing, selection), its handles moved with it; a new key takes the interpolation of
    the key before it (else of the first key), Blender's handles.  Other keys keep their
    attributes.  ``value`` is written as given (an NLA remap is the caller's).  Returns False,
    having changed nothing that :func:`update_keys` would not, where Blender's keying wrote no
    key at ``frame`` (a locked curve, Only Insert Needed with the value already there, a time
    mapping it does differently) or keyed there a value other than ``value`` (the property
    holds another value; auto handles fitted to ``value`` need a recalculation, a flushed
    update): the caller then writes the key with :func:`update_keys`."""
    kp = fcurve.keyframe_points
    n = len(kp)
    old = {name: np.empty(n, dt) for name, dt in _KEY_ATTRS}
    for name, buf in old.items():
        kp.foreach_get(name, buf)
    co0, hl0, hr0 = (np.empty(2 * n, np.float32) for _ in range(3))
    kp.foreach_get("co", co0)
    kp.foreach_get("handle_left", hl0)
    kp.foreach_get("handle_right", hr0)
    at = np.nonzero(np.abs(co0[0::2] - frame) < 1e-4)[0]
    ad = id_owner.animation_data
    scene_frame = frame
    if ad is not None and ad.use_tweak_mode and hasattr(ad, "nla_tweak_strip_time_to_scene"):
        scene_frame = float(ad.nla_tweak_strip_time_to_scene(float(frame)))
    kw = {"group": fcurve.group.name} if fcurve.group is not None else {}
    ok = False
    # index -1 for a property that is not an array (Blender refuses 0 there)
    for index in dict.fromkeys((fcurve.array_index, -1 if fcurve.array_index == 0 else fcurve.array_index)):
        try:
            ok = id_owner.keyframe_insert(fcurve.data_path, index=index, frame=scene_frame, **kw)
            break
        except TypeError:
            continue
        except RuntimeError:
            break
    m = len(kp)
    co = np.empty(2 * m, np.float32)
    kp.foreach_get("co", co)
    co = co.reshape(m, 2)
    hit = np.nonzero(np.abs(co[:, 0] - frame) < 1e-4)[0]
    if not ok or len(hit) != 1 or m - n not in (0, 1) or (m == n and len(at) != 1):
        if m != n or not np.array_equal(co.ravel(), co0):
            # Blender keyed elsewhere (another frame, a key within its 0.01 frame snap): the curve
            # as it was, for update_keys
            _restore_keys(kp, n, old, co0, hl0, hr0)
        return False
    i = int(hit[0])
    if abs(float(co[i, 1]) - value) > 1e-5 * max(1.0, abs(value)):
        # Blender keyed another value (``value`` given, not the property's; a remap it does
        # differently): its auto handles, of this key and its neighbours, fit that value and only a
        # recalculation (a flushed update) fits them to ``value``: the curve as it was, for
        # update_keys
        _restore_keys(kp, n, old, co0, hl0, hr0)
        return False
    for name, buf in old.items():
        if m == n:
            out = buf
        else:
            cur = np.empty(m, buf.dtype)
            kp.foreach_get(name, cur)
            out = np.insert(buf, i, cur[i])
            if name == "interpolation":
                out[i] = buf[i - 1] if i > 0 else (buf[0] if n else _interp_value('LINEAR'))
            elif name.startswith("handle_"):
                out[i] = cur[i]
        kp.foreach_set(name, out)
    hl, hr = np.empty(2 * m, np.float32), np.empty(2 * m, np.float32)
    kp.foreach_get("handle_left", hl)
    kp.foreach_get("handle_right", hr)
    dv = np.float32(value) - co[i, 1]
    co[i, 1] = value
    hl[2 * i + 1] += dv
    hr[2 * i + 1] += dv
    kp.foreach_set("co", co.ravel())
    kp.foreach_set("handle_left", hl)
    kp.foreach_set("handle_right", hr)
    # the evaluated copy takes the values written after Blender's keying (a tag that does not
    # evaluate the owner's animation again)
    fcurve.id_data.update_tag()
    return True


#: the F-curve property of a pose bone's rotation in each rotation mode (every Euler order:
#: ``rotation_euler``)
ROTATION_PATHS = {'QUATERNION': "rotation_quaternion", 'AXIS_ANGLE': "rotation_axis_angle"}


def rotation_channels(bones, quats, modes=None):
    """Keying channels (:func:`key_channels`) for the rotations ``quats`` ``(T, B, 4)`` wxyz of
    pose bones ``bones`` (B names; each bone's basis, as ``rotation_quaternion`` holds it,
    sign-continuous over the frames), each in its rotation mode (``modes``: B modes, default all
    ``'QUATERNION'``): ``rotation_quaternion`` as given, ``rotation_axis_angle`` (angle, x, y, z)
    or ``rotation_euler`` (radians about x, y, z in that Euler order), continuous over the frames
    as Blender's own keying keeps them (:func:`..core.rotations.euler_continuous`).  So a bone
    keeps its mode, and the animator's other actions, keyed in it, still play on it.  Each
    bone's channels are grouped under its name.  Bones of one mode are converted together."""
    q = np.asarray(quats, np.float64)
    modes = ['QUATERNION'] * len(bones) if modes is None else list(modes)
    values = [None] * len(bones)
    for mode in dict.fromkeys(modes):
        ks = [k for k, m in enumerate(modes) if m == mode]
        if mode == 'QUATERNION':
            v = q[:, ks]
        elif mode == 'AXIS_ANGLE':
            v = rot.quat_to_axis_angle_continuous(q[:, ks])
        else:
            v = rot.euler_continuous(rot.matrix_to_fixed_axes_euler(rot.quat_to_matrix(q[:, ks]), mode), mode)
        for n, k in enumerate(ks):
            values[k] = v[:, n]
    ch = []
    for name, mode, v in zip(bones, modes, values):
        path = f'pose.bones["{name}"].{ROTATION_PATHS.get(mode, "rotation_euler")}'
        ch += [(path, i, name, v[:, i]) for i in range(v.shape[1])]
    return ch


def key_channels(action, id_owner, frames, channels, interpolation: str = 'LINEAR'):
    """Key many channels of ``id_owner`` in ``action`` at the same ``frames``.

    channels: iterable of ``(data_path, index, group, values)`` with ``values``
    ``(n,)``, or ``(data_path, index, group, values, interpolation)`` for a channel keyed
    otherwise (e.g. ``'CONSTANT'`` steps).  Returns the list of F-curves written.
    """
    out = []
    for channel in channels:
        data_path, index, group, values = channel[:4]
        fc = ensure_fcurve(action, data_path, index, group, id_owner)
        out.append(set_keys(fc, frames, values, channel[4] if len(channel) > 4 else interpolation))
    return out


def action_fcurves(action, id_owner=None):
    """All F-curves of ``action`` (for ``id_owner``'s slot on the slotted API; all slots if None)."""
    if not is_slotted(action):
        return list(action.fcurves)
    out = []
    if id_owner is None:
        slots = list(action.slots)
    else:
        slot = find_slot(action, id_owner)
        slots = [] if slot is None else [slot]
    for layer in action.layers:
        for strip in layer.strips:
            for slot in slots:
                bag = strip.channelbag(slot)
                if bag is not None:
                    out.extend(bag.fcurves)
    return out


def nla_blends(id_owner) -> bool:
    """True when Blender evaluates ``id_owner``'s action through the NLA (NLA tracks present and
    NLA evaluation on, or a strip edited in tweak mode): a channel then shows the strip / action
    value blended with the tracks below (blend type, influence, blend in / out), not the value
    itself, so a key must be remapped (:func:`nla_blend_terms`) as Blender's own keying does."""
    ad = getattr(id_owner, "animation_data", None)
    if ad is None:
        return False
    return bool(ad.use_tweak_mode or (ad.use_nla and len(ad.nla_tracks)))


def nla_blend_terms(id_owner, fcurves, context=None):
    """``(a, b)``: ``(len(fcurves),)`` float64 arrays such that Blender's evaluation of
    ``id_owner`` at the scene's current frame shows ``a[k] + b[k] * v`` in channel
    ``(fcurves[k].data_path, fcurves[k].array_index)`` when ``fcurves[k]`` (a curve of the
    action being keyed: the active action, or the strip's in tweak mode) evaluates to ``v``.

    Every NLA blend of a scalar channel with the tracks below is affine in the strip's value
    (Replace ``(1-i) L + i v``, Add / Combine ``L + i v``, Subtract ``L - i v``, Multiply
    ``(1-i) L + i L v``; ``i`` the strip's influence there, blend in / out included; a strip
    above that replaces the channel gives ``b = 0``).  ``a`` and ``b`` are measured from
    Blender's own evaluation, not modelled: each curve is overridden by a constant (a
    non-additive Generator F-modifier, removed afterwards) of 0, then 1, and the scene frame is
    re-evaluated (``scene.frame_set`` on the current frame and subframe)."""
    context = context or bpy.context
    scene = context.scene
    frame = scene.frame_current, scene.frame_subframe
    mods = []
    out = np.empty((2, len(fcurves)))
    try:
        for fc in fcurves:
            m = fc.modifiers.new('GENERATOR')
            m.mode, m.poly_order, m.use_additive = 'POLYNOMIAL', 1, False
            mods.append((fc, m))
        for c in (0, 1):
            for _, m in mods:
                m.coefficients = (float(c), 0.0)
            scene.frame_set(frame[0], subframe=frame[1])
            ev = id_owner.evaluated_get(context.evaluated_depsgraph_get())
            for k, fc in enumerate(fcurves):
                v = ev.path_resolve(fc.data_path)
                out[c, k] = v[fc.array_index] if hasattr(v, "__len__") else v
    finally:
        for fc, m in mods:
            fc.modifiers.remove(m)
        scene.frame_set(frame[0], subframe=frame[1])
    return out[0], out[1] - out[0]


def nla_remap_values(id_owner, fcurves, values, context=None):
    """The values to key in ``fcurves`` (``(n,)`` float64) so that Blender shows ``values`` (``(n,)``,
    the property's units) at the scene's current frame through the NLA blending
    (:func:`nla_blend_terms`); ``values`` unchanged when :func:`nla_blends` is False.  Raises
    ``ValueError`` naming the channels whose strip cannot change what is shown (influence 0, a
    muted curve, or a strip above replacing them)."""
    values = np.asarray(values, np.float64).ravel()
    if not nla_blends(id_owner):
        return values
    a, b = nla_blend_terms(id_owner, fcurves, context)
    stuck = np.abs(b) < 1e-6
    if stuck.any():
        names = ", ".join(fcurves[k].data_path for k in np.nonzero(stuck)[0])
        raise ValueError(f"{id_owner.name!r}: {names} cannot be keyed here: the NLA shows no effect of the "
                         f"edited action at this frame (strip influence 0, a muted curve, or a strip above "
                         f"replacing it)")
    return (values - a) / b
