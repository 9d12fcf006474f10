"""Panels of the add-on (import bpy).  ``CLASSES`` lists them for registration."""
from .main import CLASSES

__all__ = ["CLASSES"]
