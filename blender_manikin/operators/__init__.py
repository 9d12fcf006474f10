"""Operators of the add-on (import bpy).  ``CLASSES`` lists them for registration."""
from .solve import CLASSES as _SOLVE
from .tools import CLASSES as _TOOLS
from .swivel_tools import CLASSES as _SWIVEL
from .retarget import CLASSES as _RETARGET
from .export import CLASSES as _EXPORT

CLASSES = _SOLVE + _TOOLS + _SWIVEL + _RETARGET + _EXPORT
