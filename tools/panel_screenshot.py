"""Blender-side half of tools/panel_screenshot.sh: pose the UI for the README's panel screenshot.

Runs inside a windowed Blender (under Xvfb) in which the extension zip was installed and enabled:

    blender --python tools/panel_screenshot.py -- --example examples/example_recording.csv \
            --ready /tmp/ready --done /tmp/done [--frame 60] [--keypoints examples/example_keypoints] \
            [--open calibration,output,retarget,export] [--unit-scale 0.01] [--ui-scale 1.25]
            [--source SCENE] [--character] [--set export_format=GLB] [--report "Solve failed: ..."]

It solves the example through the add-on's own operator (as a click on "Solve full body" does),
opens the 3D Viewport sidebar, frames the solved body, and, once the window has redrawn, keeps
writing the ``--ready`` file (JSON: the sidebar's screen position and its active tab).  The shell
script switches the sidebar to the MANIKIN tab with Ctrl+wheel (xdotool), grabs the screen
(ImageMagick ``import``) and creates ``--done``, on which Blender quits.  Any error quits Blender with status 1.
"""
import argparse
import json
import os
import sys
import traceback

import bpy


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    ap = argparse.ArgumentParser()
    ap.add_argument("--example", required=True)
    ap.add_argument("--ready", required=True)
    ap.add_argument("--done", required=True)
    ap.add_argument("--frame", type=int, default=60)
    ap.add_argument("--keypoints", default=None,
                    help="solve this keypoint file / FreeMoCap folder with the Keypoints source instead")
    ap.add_argument("--open", default="",
                    help="comma-separated sub-panels to show open (e.g. calibration,output)")
    ap.add_argument("--unit-scale", type=float, default=None,
                    help="the scene's unit scale (0.01: a scene in centimetres)")
    ap.add_argument("--ui-scale", type=float, default=None,
                    help="Preferences > Interface > Resolution Scale (1.25: the labels 25%% wider)")
    ap.add_argument("--source", default=None, choices=("FILE", "SCENE", "KEYPOINTS"),
                    help="after the solve, show this source tab (SCENE: the tracker empties mapped)")
    ap.add_argument("--character", action="store_true",
                    help="choose a character (a copy of the solved armature) in Retarget to Character")
    ap.add_argument("--set", action="append", default=[], metavar="SETTING=VALUE",
                    help="after the solve, set a panel setting (scene.manikin), e.g. export_format=GLB; repeatable")
    ap.add_argument("--report", default=None,
                    help="show this summary instead of the solve's (e.g. a failed solve's message)")
    return ap.parse_args(argv)


ARGS = parse_args()


def fail(msg):
    print(f"panel_screenshot: {msg}", file=sys.stderr, flush=True)
    os._exit(1)


def view3d():
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                region = next(r for r in area.regions if r.type == 'WINDOW')
                return window, area, region
    fail("no 3D Viewport in the startup screen")


def prepare():
    if ARGS.ui_scale:
        bpy.context.preferences.view.ui_scale = ARGS.ui_scale
    if not hasattr(bpy.ops, "manikin") or not hasattr(bpy.context.scene, "manikin"):
        fail("the blender_manikin extension is not enabled")
    # The factory startup scene's cube would hide the body.
    for obj in list(bpy.data.objects):
        if obj.type == 'MESH':
            bpy.data.objects.remove(obj)
    open_panels(filter(None, (n.strip() for n in ARGS.open.split(","))))
    if ARGS.unit_scale:
        us = bpy.context.scene.unit_settings
        us.system, us.scale_length = 'METRIC', ARGS.unit_scale
        if ARGS.unit_scale == 0.01:
            us.length_unit = 'CENTIMETERS'
    settings = bpy.context.scene.manikin
    if ARGS.keypoints:
        settings.source = 'KEYPOINTS'
        settings.keypoint_path = os.path.abspath(ARGS.keypoints)
    else:
        settings.source = 'FILE'
        settings.filepath = os.path.abspath(ARGS.example)
    result = bpy.ops.manikin.solve_full_body('EXEC_DEFAULT')
    if 'FINISHED' not in result:
        fail(f"solve failed: {result} {settings.last_report}")
    arm = next(o for o in bpy.data.objects if o.type == 'ARMATURE')
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj == arm)
    bpy.context.view_layer.objects.active = arm
    bpy.context.scene.frame_set(ARGS.frame)
    if ARGS.character:
        character = arm.copy()
        character.data = arm.data.copy()
        character.name = "Character"
        for key in list(character.keys()):
            if key.startswith("manikin"):
                del character[key]
        bpy.context.scene.collection.objects.link(character)
        settings.retarget_target = character
    if ARGS.source:
        settings.source = ARGS.source
        if ARGS.source == 'SCENE':
            bpy.ops.manikin.map_devices()
    for assignment in ARGS.set:
        name, _, value = assignment.partition("=")
        if not hasattr(settings, name):
            fail(f"--set {assignment}: scene.manikin has no setting {name!r}")
        current = getattr(settings, name)
        if isinstance(current, bool):
            value = value.lower() in ("1", "true", "on")
        elif isinstance(current, (int, float)):
            value = type(current)(float(value))
        setattr(settings, name, value)              # an enum or a text as given
    if ARGS.report is not None:
        settings.last_report = ARGS.report

    window, area, region = view3d()
    space = area.spaces.active
    space.show_region_ui = True
    space.overlay.show_floor = True
    # A three-quarter view from the front left, a little above the body, centred on its hips.
    from mathutils import Euler, Vector
    deps = bpy.context.evaluated_depsgraph_get()
    arm_eval = arm.evaluated_get(deps)
    heads = [arm_eval.matrix_world @ pb.head for pb in arm_eval.pose.bones]
    centre = sum(heads, Vector()) / len(heads)
    r3d = space.region_3d
    r3d.view_perspective = 'PERSP'
    r3d.view_location = centre
    r3d.view_rotation = Euler((1.40, 0.0, -0.50), 'XYZ').to_quaternion()
    r3d.view_distance = 4.2
    space.lens = 50
    area.tag_redraw()


def open_panels(names):
    """Show the sub-panels ``names`` (``calibration``, ``output``, ``retarget``, ``export``) open:
    registered again without DEFAULT_CLOSED.  Blender puts a panel registered again last among
    its siblings, so every sub-panel of Solve Full Body is registered again, in the add-on's order
    (else an opened Calibration was drawn below Retarget to Character)."""
    names = set(names)
    if not names:
        return
    for name in names:
        if getattr(bpy.types, f"MANIKIN_PT_{name}", None) is None:
            fail(f"no panel MANIKIN_PT_{name}")
    module = sys.modules[bpy.types.MANIKIN_PT_solve.__module__]       # panels/main.py, its CLASSES
    children = [c for c in module.CLASSES if getattr(c, "bl_parent_id", "") == "MANIKIN_PT_solve"]
    for cls in reversed(children):
        bpy.utils.unregister_class(cls)
    for cls in children:
        if cls.__name__[len("MANIKIN_PT_"):] in names:
            cls.bl_options = set(getattr(cls, "bl_options", set())) - {'DEFAULT_CLOSED'}
        bpy.utils.register_class(cls)


def sidebar_info():
    """Where the sidebar is (X screen coordinates, origin top left), its left edge (``left``, the
    border a user drags to resize it), its ``width`` in pixels, and which tab it shows."""
    window, area, _ = view3d()
    sidebar = next(r for r in area.regions if r.type == 'UI')
    # Over the tab strip at the sidebar's right edge, near its top: no button there could take
    # the wheel as a value change.
    scale = bpy.context.preferences.system.ui_scale
    return {"x": sidebar.x + sidebar.width - int(10 * scale),
            "y": window.height - (sidebar.y + sidebar.height) + int(30 * scale),
            "left": sidebar.x, "width": sidebar.width, "scale100": int(round(100 * scale)),
            "category": getattr(sidebar, "active_panel_category", "")}


STATE = {"ticks": 0}


def tick():
    try:
        STATE["ticks"] += 1
        if STATE["ticks"] == 1:
            prepare()
            return 0.5
        if STATE["ticks"] < 6:          # a few redraws for the UI to settle
            for window in bpy.context.window_manager.windows:
                for area in window.screen.areas:
                    area.tag_redraw()
            return 0.5
        # The sidebar's tab cannot be chosen from Python in every version (read-only in 4.3), so
        # the shell script switches it as a user would (Ctrl+wheel over the sidebar) until this
        # file says MANIKIN.
        with open(ARGS.ready + ".tmp", "w") as fh:
            json.dump(sidebar_info(), fh)
        os.replace(ARGS.ready + ".tmp", ARGS.ready)
        if os.path.exists(ARGS.done):
            bpy.ops.wm.quit_blender()
            return None
        return 0.2
    except Exception:
        traceback.print_exc()
        fail("error while preparing the screenshot")


bpy.app.timers.register(tick, first_interval=1.0)
