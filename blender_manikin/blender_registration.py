"""Registration of every Blender class of the add-on and of ``Scene.manikin``.

``register()`` → ``unregister()`` → ``register()`` works cleanly: classes are
registered in dependency order (property groups first) and unregistered in
reverse; ``Scene.manikin`` is added after its property group and removed
before it.  No handlers, keymaps or timers stay behind (the solve operator's
timer lives only while a modal solve runs and is removed when it ends; the ``load_post``
handler that carries length settings of files saved by earlier versions, :mod:`.blender.units`,
is removed with the add-on).
"""
from __future__ import annotations

import bpy

from .blender import properties, units
from .blender.class_registry import register_classes, unregister_classes
from . import operators, panels

CLASSES = properties.CLASSES + operators.CLASSES + panels.CLASSES


def register():
    register_classes(CLASSES)            # tolerates a second register() without unregister()
    bpy.types.Scene.manikin = bpy.props.PointerProperty(type=properties.MANIKIN_Settings)
    units.register_migration()


def unregister():
    from .operators import solve
    solve.abort_active(bpy.context)      # a modal solve in progress: its timer and status text
    units.unregister_migration()
    if hasattr(bpy.types.Scene, "manikin"):
        del bpy.types.Scene.manikin
    unregister_classes(CLASSES)
