"""The version of blender_manikin: the one place it is written (build_addon.py checks that
``bl_info["version"]`` in the package agrees)."""
__version__ = "0.1.0"
