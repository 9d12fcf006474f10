"""Panels of the add-on (import bpy).  ``CLASSES`` lists them for registration."""
from .main import CLASSES as _MAIN
from .swivel_panel import CLASSES as _SWIVEL

CLASSES = _MAIN + _SWIVEL

__all__ = ["CLASSES"]
