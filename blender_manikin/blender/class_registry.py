"""Registering Blender classes so that a second register() without unregister() is harmless."""
from __future__ import annotations

import bpy


def is_registered(cls) -> bool:
    return getattr(cls, "is_registered", False) or getattr(bpy.types, cls.__name__, None) is cls


def register_classes(classes):
    """Register ``classes`` in order, replacing any already-registered copy."""
    for cls in classes:
        if is_registered(cls):
            bpy.utils.unregister_class(cls)
        bpy.utils.register_class(cls)


def unregister_classes(classes):
    """Unregister ``classes`` in reverse order, skipping those not registered."""
    for cls in reversed(classes):
        if is_registered(cls):
            bpy.utils.unregister_class(cls)
