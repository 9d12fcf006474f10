"""The panel's bone map editor: ``scene.manikin.retarget_bone_map``, one row per source joint.

A row (:class:`~.properties.MANIKIN_BoneMapItem`) is the joint (its ``name``), the character's
bone that follows it (``bone``, empty: none) and the segment's twist bones (``twist``, base to
tip, comma-separated).  The rows are filled from the chosen map (Guess, a preset, a saved JSON)
for the chosen character -- by **Load Map** (``manikin.load_bone_map``), and by themselves when
the character, the map choice or the map file changes while the rows hold no edits.  Changing a
row by hand marks the rows edited and switches the choice to ``'EDITED'`` (the retarget then uses
the rows as they are); edited rows are never replaced except by Load Map.

The conversions are :func:`..core.bone_maps.bone_map_rows` / :func:`..core.bone_maps.bone_map_from_rows`
and :func:`..core.bone_maps.save_bone_map` / :func:`..core.bone_maps.load_bone_map` (JSON);
this module only moves rows between them and the collection.
"""
from __future__ import annotations

import os

from ..core import bone_maps

#: between the names of a row's twist bones
TWIST_SEPARATOR = ", "
#: under the user's script folder: where Save Map proposes to write
USER_FOLDER = os.path.join("presets", "blender_manikin", "bone_maps")

_FILLING = [False]        # rows being written by the add-on, not edited by the user


def twist_text(bones) -> str:
    """A row's ``twist`` text of the bone names ``bones``."""
    return TWIST_SEPARATOR.join(bones)


def twist_bones(text: str) -> list:
    """The bone names of a row's ``twist`` text (comma-separated; blanks dropped)."""
    return [b.strip() for b in str(text or "").split(",") if b.strip()]


def rows(settings) -> list:
    """``[(joint, bone, [twist bones])]`` of the editor's rows, in their order."""
    return [(it.name, it.bone, twist_bones(it.twist)) for it in settings.retarget_bone_map]


def fill(settings, bmap, source: str = "") -> None:
    """Replace the rows by ``bmap``'s (one per joint, :func:`..core.bone_maps.bone_map_rows`);
    the rows are then unedited.  ``source``: what they came from, shown under the list."""
    bm = bone_maps.as_bone_map(bmap)
    _FILLING[0] = True
    try:
        coll = settings.retarget_bone_map
        coll.clear()
        for joint, bone, tw in bone_maps.bone_map_rows(bm):
            it = coll.add()
            it.name, it.bone, it.twist = joint, bone, twist_text(tw)
        settings.retarget_bone_map_index = 0
        settings.retarget_bone_map_name = bm.name
        settings.retarget_bone_map_edited = False
        settings.retarget_bone_map_source = source
    finally:
        _FILLING[0] = False


def to_bone_map(settings) -> bone_maps.BoneMap:
    """The rows as a :class:`~..core.bone_maps.BoneMap` (not validated), named as loaded."""
    return bone_maps.bone_map_from_rows(rows(settings), settings.retarget_bone_map_name or "edited")


def checked_bone_map(settings, target_obj) -> bone_maps.BoneMap:
    """The rows as a map checked against the character ``target_obj``: ``ValueError`` for no
    rows, and as :func:`..core.bone_maps.validate_bone_map` says (a bone the character does not
    have names the joint and the bone; the pelvis must have a bone; no bone twice)."""
    if not len(settings.retarget_bone_map):
        raise ValueError("the bone map list is empty: press Load Map to fill it")
    bones = target_obj.data.bones.keys() if target_obj is not None and target_obj.type == 'ARMATURE' else None
    return bone_maps.validate_bone_map(to_bone_map(settings), bones)


def resolve_choice(settings, target_obj):
    """``(BoneMap, notes)`` of the panel's map choice (Guess, a preset, From File) for
    ``target_obj`` (:func:`.retarget_apply.resolve_bone_map`); ``ValueError`` for 'EDITED'."""
    import bpy
    from . import retarget_apply
    if settings.retarget_map == 'EDITED':
        raise ValueError("the map choice is the edited list: choose Guess, a preset or From File to load")
    path = bpy.path.abspath(settings.retarget_map_file) if settings.retarget_map_file else None
    return retarget_apply.resolve_bone_map(settings.retarget_map.lower(), target_obj, path)


def load_choice(settings, target_obj):
    """Fill the rows from the panel's map choice for ``target_obj``; returns ``(BoneMap, notes)``."""
    bmap, notes = resolve_choice(settings, target_obj)
    label = dict((k, n) for k, n, _ in _choice_items(settings)).get(settings.retarget_map, settings.retarget_map)
    fill(settings, bmap, f"{label} for {target_obj.name}" if target_obj is not None else label)
    return bmap, notes


def _choice_items(settings):
    prop = settings.bl_rna.properties["retarget_map"]
    return [(i.identifier, i.name, i.description) for i in prop.enum_items]


def auto_fill(settings) -> bool:
    """Fill the rows from the map choice when they are empty or hold no edits (a character and a
    choice other than 'EDITED' needed); a map that cannot be made (no file yet) leaves them.
    Returns True when filled."""
    target = settings.retarget_target
    if target is None or settings.retarget_map == 'EDITED':
        return False
    if len(settings.retarget_bone_map) and settings.retarget_bone_map_edited:
        return False
    try:
        load_choice(settings, target)
    except (ValueError, OSError, KeyError, TypeError):
        return False
    return True


def row_edited(settings) -> None:
    """A row changed by the user: the rows are edited and the retarget uses them ('EDITED')."""
    if _FILLING[0]:
        return
    settings.retarget_bone_map_edited = True
    if settings.retarget_map != 'EDITED':
        settings.retarget_map = 'EDITED'


def user_folder(create: bool = False) -> str:
    """The folder for saved bone maps in the user's Blender scripts folder
    (``.../scripts/presets/blender_manikin/bone_maps``)."""
    import bpy
    return bpy.utils.user_resource('SCRIPTS', path=USER_FOLDER, create=create)


def joint_label(joint: str) -> str:
    """``left_elbow`` -> ``Left Elbow``."""
    return joint.replace("_", " ").title()
