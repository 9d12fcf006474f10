"""The scene's length unit: Blender units against the metres of the core.

The core (:mod:`blender_manikin.core`) works in metres.  A Blender scene's unit is
``scene.unit_settings.scale_length`` metres (1 by default; 0.01 in a scene set up in centimetres,
as for Unreal Engine), which is what Blender shows for every length property.  The add-on converts
at the boundary, gather → create: scene objects read as trackers are taken into metres
(:mod:`.scene_trackers`), the solve is written in scene units (:func:`result_in_scene_units`:
a 1.75 m performer is 175 units tall in a centimetre scene, 1.75 in a metre one), and the length
settings (height, arm span, soles, floor height) hold metres and show them in the scene's unit
(:func:`length_property`).  With the unit system *None*, a unit is a metre, as the FBX exporter
takes it.
"""
from __future__ import annotations

from bpy.props import FloatProperty


def metres_per_unit(scene) -> float:
    """Metres in one Blender unit of ``scene`` (1.0 when its unit system is None)."""
    us = getattr(scene, "unit_settings", None)
    if us is None or us.system == 'NONE':
        return 1.0
    k = float(us.scale_length)
    return k if k > 0 else 1.0


def result_in_scene_units(result, scene):
    """``result`` (:class:`~blender_manikin.core.pose_result.PoseResult`, metres) in the scene's
    units: itself in a metre scene, else :meth:`~..core.pose_result.PoseResult.scaled`."""
    k = metres_per_unit(scene)
    return result if k == 1.0 else result.scaled(1.0 / k)


def length_property(metres_attr, name, description, lo=None, hi=None):
    """A ``FloatProperty`` (unit ``LENGTH``) that shows and takes the length kept in metres in the
    property group's ``metres_attr``, converted to and from the scene's unit, so that it reads
    "1.75 m" in a metre scene and "175 cm" in a centimetre one.  Typed values are clamped to
    ``[lo, hi]`` metres (None: open)."""

    def get(self):
        return float(getattr(self, metres_attr)) / metres_per_unit(self.id_data)

    def set(self, value):
        v = float(value) * metres_per_unit(self.id_data)
        if lo is not None:
            v = max(v, lo)
        if hi is not None:
            v = min(v, hi)
        setattr(self, metres_attr, v)

    # precision 3: Blender counts a length's digits from its first one, so 2 showed 1.75 m as "1.8 m"
    return FloatProperty(name=name, unit='LENGTH', get=get, set=set, description=description, precision=3)


#: the length settings kept in metres behind :func:`length_property` (``<name>_m``)
LENGTH_SETTINGS = ("height", "arm_span", "sole", "floor_height")


def migrate_length_settings(scenes) -> int:
    """Carry length settings saved by an earlier version of the add-on (an ID property
    ``height`` etc. on ``scene.manikin``, in metres) into their ``<name>_m`` properties, so that
    a file's typed height is not lost, and drop the old entries.  Returns how many moved."""
    moved = 0
    for sc in scenes:
        group = getattr(sc, "manikin", None)
        if group is None:
            continue
        for name in LENGTH_SETTINGS:
            if name not in group.keys():
                continue
            try:
                setattr(group, f"{name}_m", float(group[name]))      # clamped to the setting's range
                moved += 1
            except (TypeError, ValueError):
                pass
            del group[name]
    return moved


def _on_load(_dummy=None):
    import bpy
    migrate_length_settings(bpy.data.scenes)


def register_migration():
    """Migrate each file as it is loaded, and the file open now (once Blender can write to it)."""
    import bpy
    handler = bpy.app.handlers.persistent(_on_load)
    if handler not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(handler)
    if not bpy.app.timers.is_registered(_on_load):
        bpy.app.timers.register(_on_load, first_interval=0.0)


def unregister_migration():
    import bpy
    while _on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_on_load)
    if bpy.app.timers.is_registered(_on_load):
        bpy.app.timers.unregister(_on_load)
