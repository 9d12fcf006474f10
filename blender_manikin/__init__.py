"""blender_manikin: full-body animation from sparse VR trackers (MANIKIN neural-analytic IK).

The numpy core (``blender_manikin.core``) never imports bpy; everything that
touches Blender lives in ``operators/``, ``panels/`` and ``blender/`` and is
imported only by :func:`register`.
"""
from .core.version import __version__  # noqa: F401  (written in core/version.py)

bl_info = {
    "name": "MANIKIN full-body solver",
    "author": "blender_manikin developers",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "3D Viewport > Sidebar > MANIKIN",
    "description": "Full-body animation from VR head and hand trackers (neural-analytic IK)",
    "category": "Animation",
}


def register():
    from . import blender_registration
    blender_registration.register()


def unregister():
    from . import blender_registration
    blender_registration.unregister()
