"""Shared test setup: where ../shared is, and the markers of each test module.

The repository root is on ``sys.path`` through ``pythonpath`` in pyproject.toml's pytest
settings, so tests import ``blender_manikin`` (and this folder's helpers) as installed.

Markers (``pytest -m ...``): ``blender`` (needs the bpy module), ``training`` (needs torch and
onnx), ``slow`` (builds zips or wheels, starts Blender processes, or solves many recordings).
The fast subset is ``pytest -m "not slow" tests``.
"""
import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED = os.path.join(os.path.dirname(ROOT), "shared")

_BLENDER = ("test_blender_", "test_extension_install")
_TRAINING = ("test_training", "test_model_dap")
_SLOW = ("test_extension_install", "test_packaging", "test_standing", "test_training.py", "test_model_dap",
         "test_convert", "test_blender_cli", "test_blender_swivel_rig")


def pytest_collection_modifyitems(config, items):
    for item in items:
        name = os.path.basename(str(item.fspath))
        if name.startswith(_BLENDER):
            item.add_marker(pytest.mark.blender)
        if name.startswith(_TRAINING):
            item.add_marker(pytest.mark.training)
        if name.startswith(_SLOW):
            item.add_marker(pytest.mark.slow)


def pytest_sessionfinish(session, exitstatus):
    session.config.manikin_exitstatus = int(exitstatus)


def pytest_unconfigure(config):
    """After the last report line: a process that ran Blender 4.2's glTF exporter in the bpy
    module would crash on its way out (status 139 after every test passed), so it leaves by
    ``os._exit`` with pytest's own status (:func:`blender_manikin.blender.gltf_export.exit_crashes`)."""
    gltf = sys.modules.get("blender_manikin.blender.gltf_export")
    if gltf is not None and gltf.exit_crashes():
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(getattr(config, "manikin_exitstatus", 0))


@pytest.fixture
def addon():
    """An empty factory scene with the add-on registered (Blender tests; bpy imported here only).
    ``test_blender_addon.py`` has its own, with a stand-in solver."""
    import blender_manikin
    from blender_util import fresh_scene
    fresh_scene()
    blender_manikin.register()
    yield
    blender_manikin.unregister()
