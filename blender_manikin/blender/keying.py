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
``fcurve.update()``.  ``keyframe_insert`` is never used.

Frames are scene frames (float, ``co[0]``); values are in the RNA property's
units (radians for rotations and the swivel angles, metres for locations).
"""
from __future__ import annotations

import numpy as np

import bpy


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


def assign_action(id_owner, action):
    """Make ``action`` the active action of ``id_owner`` (and, slotted, assign its slot)."""
    ad = id_owner.animation_data or id_owner.animation_data_create()
    ad.action = action
    if is_slotted(action):
        slot = ensure_slot(action, id_owner)
        if ad.action_slot != slot:
            ad.action_slot = slot
    return ad


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
