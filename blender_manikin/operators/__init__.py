"""Operators of the add-on (import bpy).  ``CLASSES`` lists them for registration."""
from .solve import CLASSES as _SOLVE
from .tools import CLASSES as _TOOLS
from .swivel_tools import CLASSES as _SWIVEL

CLASSES = _SOLVE + _TOOLS + _SWIVEL
