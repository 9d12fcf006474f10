"""Scene settings of the add-on (``scene.manikin``) and their conversion to a :class:`SolveConfig`."""

import json

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty, IntProperty,
                       PointerProperty, StringProperty)
from bpy.types import PropertyGroup

from ..core import formats
from ..core.skeleton import LENGTH_RANGES
from ..core.solve import FLOOR_FROM_HEIGHT
from ..core.devices import DEVICES, LABELS as DEVICE_LABELS  # noqa: F401  (labels: the panel)
from .units import length_property

_AXES_ITEMS = [
    ('AUTO', "From File", "Axes from the file's metadata, else the format's default "
     "(CSV: OpenXR, BSOR: Unity)"),
    ('OPENXR', "OpenXR / SteamVR", "Right-handed, +Y up, -Z forward"),
    ('UNITY', "Unity", "Left-handed, +Y up, +Z forward"),
    ('BLENDER', "Blender", "Right-handed, +Z up, -Y forward"),
    ('UNREAL', "Unreal Engine", "Left-handed, +Z up, +X forward (Unreal's world and component axes)"),
]
_UNITS_ITEMS = [
    ('AUTO', "From File", "Units from the file's metadata, else metres"),
    ('M', "Metres", ""), ('CM', "Centimetres", ""), ('MM', "Millimetres", ""),
]

_preset_items_cache = []


def _preset_items(self, context):
    """Enum items of the device offsets presets (kept referenced: Blender requires it)."""
    global _preset_items_cache
    if not _preset_items_cache:
        try:
            from ..core import device_offsets
            names = device_offsets.PRESET_NAMES
            desc = {n: device_offsets.get_preset(n).get("description", "") for n in names}
        except Exception:          # pragma: no cover - module missing
            names, desc = ("none",), {"none": "Device poses are the joint poses"}
        implied = ", ".join(f"{f.default_offsets.replace('_', ' ').title()} for {'/'.join(f.extensions)}"
                            for f in formats.READERS.values() if f.default_offsets != "none")
        _preset_items_cache = [("auto", "Auto", "From the recording: its '# offsets:' metadata, "
                                                f"{implied}, else None, unless the take shows a headset "
                                                "(its T-pose, or a head named HMD, Main Camera, ...): "
                                                "Openxr Generic")] + \
            [(n, n.replace("_", " ").title() if n != "none" else "None", desc[n]) for n in names]
    return _preset_items_cache


def _armature_poll(self, obj):
    return obj.type == 'ARMATURE'


def _character_poll(self, obj):
    from .armature import PROP_BODY
    return obj.type == 'ARMATURE' and PROP_BODY not in obj.keys()


def _bone_map_items(edited=True):
    from ..core.bone_maps import PRESETS
    return [('AUTO', "Guess", "From the character's bone names and hierarchy (presets first)")] + \
        [(p.upper(), p.replace("_", " ").title().replace("Ue", "Unreal UE").replace("Vrm", "VRM"),
          f"The {p} preset") for p in PRESETS] + [('FILE', "From File", "A saved bone map (JSON)")] + \
        ([('EDITED', "Edited List", "The bone map list below as edited (changing a row chooses this)")]
         if edited else [])


def fbx_preset_items():
    """Enum items of the FBX export presets (:mod:`.fbx_presets`)."""
    from .fbx_presets import DESCRIPTIONS, PRESET_NAMES
    return [(n.upper(), n.title(), DESCRIPTIONS[n]) for n in PRESET_NAMES]


def export_format_items():
    """Enum items of the export formats: FBX (with its presets, :mod:`.fbx_presets`) and glTF
    binary (:mod:`.gltf_export`)."""
    return [('FBX', "FBX", "FBX with the preset's axes, units and bones (Blender, Unity, Unreal)"),
            ('GLB', "glTF Binary", "glTF binary (.glb): Y up, metres, deforming bones, the take sampled at every "
                                   "frame (Godot, three.js, Babylon.js, Unity with glTFast)")]


def _retarget_inputs_changed(self, context):
    """The character, the map choice or the map file changed: refill the bone map list unless it
    holds edits (:func:`.bone_map_list.auto_fill`)."""
    from . import bone_map_list
    bone_map_list.auto_fill(self)


def _row_edited(self, context):
    """A bone map row changed (by the user, or by a script): the retarget uses the edited list."""
    from . import bone_map_list
    bone_map_list.row_edited(self.id_data.manikin)


class MANIKIN_DeviceSource(PropertyGroup):
    """A scene object (optionally one of its bones) standing in for a tracker device."""
    object: PointerProperty(name="Object", type=bpy.types.Object,
                            description="Animated object whose world transform is this device's pose")
    bone: StringProperty(name="Bone", default="",
                         description="Bone of an armature object to use instead of the object itself")


class MANIKIN_BoneMapItem(PropertyGroup):
    """A row of the bone map editor: a source joint (``name``, one of the body model's joints)
    and the character's bone that follows it."""
    bone: StringProperty(name="Bone", default="", update=_row_edited,
                         description="The character's bone that follows this joint (empty: none; the "
                                     "joint's rotation then goes to its neighbours)")
    twist: StringProperty(name="Twist Bones", default="", update=_row_edited,
                          description="Twist bones of this joint's segment, from its base to its tip, "
                                      "comma-separated; each gets a share of the segment's twist")


def _layout_items():
    from ..core.keypoint_layouts import LAYOUTS
    return [('AUTO', "Detect", "Told from the file: its layout field, the point count or the column names")] + \
        [(n.upper(), f.description, _layout_tip(n, f)) for n, f in LAYOUTS.items()]


def _layout_tip(name, layout):
    """The layout menu's tooltip: a video layout's point count; a marker set is read by its
    marker names (its joint centres and the two pelvis midpoints are computed from them)."""
    from ..core.keypoint_layouts import MARKER_LAYOUTS
    if name in MARKER_LAYOUTS:
        return "Marker names (TRC / C3D); the joint centres are computed from the markers"
    return f"{len(layout.points)} points"


_UP_ITEMS = [('AUTO', "Detect", "Told from the body: the shoulders stand above the ankles")] + \
    [(a.upper(), a.upper(), f"The file's up axis is {a}") for a in ("+y", "+z", "-y", "-z", "+x", "-x")]


class MANIKIN_Settings(PropertyGroup):
    """Settings of the "Solve full body" panel (``scene.manikin``)."""
    source: EnumProperty(
        name="Source", default='FILE',
        items=[('FILE', "Recording", "A tracker recording: "
                + ", ".join(f"{'/'.join(f.extensions)} ({f.description})"
                            for f in formats.READERS.values() if f.kind == "trackers")),
               ('SCENE', "Scene", "Animated objects or bones in this scene, mapped to devices"),
               ('KEYPOINTS', "Keypoints", "3D keypoints from markerless or marker capture: a FreeMoCap "
                "folder's mediapipe_body_3d_xyz.npy, an .npy / .npz array, a keypoint CSV or JSON (EasyMocap, "
                "OpenPose 3-D, MMPose, MediaPipe), an OpenSim .trc "
                "(Pose2Sim) or a marker capture .c3d (Vicon, Qualisys); solved by HybrIK twist-and-swing IK")])
    keypoint_path: StringProperty(
        name="Keypoints", subtype='FILE_PATH', default="",
        description="Keypoint file: FreeMoCap output_data/mediapipe_body_3d_xyz.npy (or the recording "
                    "folder), .npy / .npz array (frames x points x 3), CSV with time and <point>_x/_y/_z, a "
                    "keypoint JSON (MMPose results, MediaPipe landmark lists) or a folder of per-frame JSON "
                    "files (EasyMocap keypoints3d, OpenPose --3d), or "
                    "an OpenSim .trc of markers named as points (Pose2Sim), or a .trc / .c3d of anatomical "
                    "markers (Plug-in Gait, OpenCap; C3D from Vicon, Qualisys, OptiTrack, Cortex)")
    keypoint_from: EnumProperty(name="From", default='FILE',
                                items=[('FILE', "File", "A keypoint file or FreeMoCap folder"),
                                       ('OBJECTS', "Scene Objects", "Animated objects (empties) named after "
                                        "a layout's points, e.g. FreeMoCap's or a markerless add-on's "
                                        "left_wrist, left_hip, ...: the objects of a collection"),
                                       ('ARMATURE', "Armature", "An animated armature (a markerless capture's "
                                        "FBX, an imported BVH, another rig's animation): each joint is the "
                                        "world position of its mapped bone's head")],
                                description="Where the keypoints come from")
    keypoint_armature: PointerProperty(type=bpy.types.Object, name="Armature", poll=_character_poll,
                                       description="The animated armature whose bones give the keypoints "
                                                   "(not a MANIKIN solve's own)")
    keypoint_bone_map: EnumProperty(name="Bone Map", items=_bone_map_items(edited=False), default='AUTO',
                                    description="Which of the armature's bones stands on each joint (the "
                                                "retarget's maps)")
    keypoint_floor: EnumProperty(name="Floor", default='AUTO',
                                 items=[('AUTO', "Auto", "An armature's heights as they are (its floor is the "
                                         "scene's); a file's or objects' floor found under the feet"),
                                        ('FEET', "Under the Feet", "The floor found under the feet is moved to "
                                         "z = 0 and the body stands on it on its Shoe Soles"),
                                        ('KEEP', "Keep Heights", "The joints stay at the heights given (the "
                                         "soles lift nothing): the source's floor is the scene's")],
                                 description="Where the solved body stands")
    keypoint_map_file: StringProperty(name="Map File", subtype='FILE_PATH', default="",
                                      description="A saved bone map (JSON: joint -> bone)")
    keypoint_collection: PointerProperty(type=bpy.types.Collection, name="Collection",
                                         description="The collection of the keypoint objects (its children's too), "
                                                     "named after the points of a layout")
    keypoint_layout: EnumProperty(name="Layout", items=_layout_items(), default='AUTO',
                                  description="Keypoint layout of the file")
    keypoint_units: EnumProperty(name="Units", items=[('AUTO', "Detect", "Told from the leg's length"),
                                                      ('M', "Metres", ""), ('CM', "Centimetres", ""),
                                                      ('MM', "Millimetres", "")], default='AUTO')
    keypoint_up: EnumProperty(name="Up Axis", items=_UP_ITEMS, default='AUTO')
    keypoint_subject_file: StringProperty(
        name="Subject File", subtype='FILE_PATH', default="",
        description="A Vicon subject parameter file (.mp or .vsk) for a Plug-in Gait .trc / .c3d: the subject's "
                    "knee, ankle and elbow widths and height (empty: a <Subject>.mp / .vsk beside the file, or the "
                    "folder's only .mp, is used when there is one)")
    keypoint_person: StringProperty(
        name="Person", default="all",
        description="In a keypoint file with several people (a 4-D array, a CSV with a person column): the "
                    "person to solve, their label or 0-based index (all: each person onto a new armature "
                    "of their own, MANIKIN_<file>_p<label>, in one undo step)")
    use_keypoint_rate: BoolProperty(name="Set Rate", default=False,
                                    description="Give the sample rate of a keypoint file that has no times "
                                                "(else 30 Hz is assumed, and said)")
    keypoint_rate: FloatProperty(name="Rate", default=30.0, min=1.0, max=1000.0,
                                 description="Samples per second of a keypoint file without times")
    smoothing_mode: EnumProperty(name="Smoothing", default='AUTO',
                                 items=[('AUTO', "Auto", "Each tracker or keypoint gets the Savitzky-Golay filter "
                                         "its own measured noise calls for: clean ones are left as they are, "
                                         "noisy ones are smoothed more"),
                                        ('WINDOW', "Window", "One Savitzky-Golay window, in seconds, for every "
                                         "tracker or keypoint")])
    smoothing: FloatProperty(name="Window", default=0.4, min=0.0, max=3.0, unit='TIME_ABSOLUTE',
                             description="Savitzky-Golay window over the tracker poses or keypoints, seconds "
                                         "(0: off); longer removes more noise and more fast detail")
    fix_sides: BoolProperty(name="Fix Left/Right Swaps", default=True,
                            description="Keypoints: give a leg's or arm's points back their side where the "
                                        "detector labelled them as the other side's for a few frames (the "
                                        "knees would cross). Trackers: swap the controllers (or foot trackers) "
                                        "back when the left one was on the right for the whole take. Off: the "
                                        "labels as read")
    despike: BoolProperty(name="Remove Spikes", default=True,
                          description="Remove samples that stand 30 cm or more off their point's path for "
                                      "one to three frames (a detector's misplacements) and bridge them; "
                                      "off: every sample as read")
    ik: EnumProperty(name="IK", default='ADAPTIVE',
                     items=[('ADAPTIVE', "Adaptive", "HybrIK adaptive: each bone aims at its keypoint from "
                             "where the chain actually is, so errors do not accumulate"),
                            ('NAIVE', "Naive", "Each bone takes the direction between its two keypoints")])
    filepath: StringProperty(name="Recording", subtype='FILE_PATH', default="",
                             description="Tracker recording (" + ", ".join(formats.input_extensions()) + ")")
    layout_file: StringProperty(name="Layout", subtype='FILE_PATH', default="",
                                description="Layout file (JSON) fixing the columns, time, units and axes of a "
                                            "wide-layout CSV or JSON recording (blender-manikin solve "
                                            "--save-layout writes one); empty: detected")
    axes: EnumProperty(name="Axes", items=_AXES_ITEMS, default='AUTO')
    units: EnumProperty(name="Units", items=_UNITS_ITEMS, default='AUTO')
    use_scene_fps: BoolProperty(name="Scene Frame Rate", default=True,
                                description="Solve at the scene's frame rate (else at FPS)")
    fps: FloatProperty(name="FPS", default=60.0, min=1.0, max=1000.0,
                       description="Frames per second of the solve")

    head: PointerProperty(type=MANIKIN_DeviceSource, name="Head")
    left_hand: PointerProperty(type=MANIKIN_DeviceSource, name="Left Hand")
    right_hand: PointerProperty(type=MANIKIN_DeviceSource, name="Right Hand")
    pelvis: PointerProperty(type=MANIKIN_DeviceSource, name="Pelvis")
    left_foot: PointerProperty(type=MANIKIN_DeviceSource, name="Left Foot")
    right_foot: PointerProperty(type=MANIKIN_DeviceSource, name="Right Foot")

    calibration: EnumProperty(
        name="Calibration", default='AUTO',
        items=[('AUTO', "Automatic", "Calibrate on the most T-pose-like moment; if there is none, "
                "stature from the standing head height"),
               ('TPOSE', "T-Pose Time", "Calibrate body size and device rotations on the T-pose "
                "at the given time"),
               ('MEASURE', "Measurements", "Use the typed height and arm span")])
    calibration_take: StringProperty(name="Calibration Take", subtype='FILE_PATH', default="",
                                     description="Trackers: calibrate on the T-pose of this recording (the "
                                                 "session's calibration take: the same performer and trackers) "
                                                 "instead of the solved take's own (empty: its own)")
    tpose_time: FloatProperty(name="T-Pose Time", default=0.0, min=0.0, unit='TIME_ABSOLUTE',
                              description="Seconds after the first tracker sample")
    # lengths are kept in metres (the *_m properties) and shown in the scene's unit (units.py)
    height_m: FloatProperty(default=1.75, min=LENGTH_RANGES["height"][0], max=LENGTH_RANGES["height"][1],
                            options={'HIDDEN'})
    height: length_property("height_m", "Height", "Performer's stature (barefoot)", *LENGTH_RANGES["height"])
    use_height: BoolProperty(name="Override Height", default=False,
                             description="Use the typed height instead of the measured stature")
    arm_span_m: FloatProperty(default=0.0, min=LENGTH_RANGES["arm_span"][0], max=LENGTH_RANGES["arm_span"][1],
                              options={'HIDDEN'})
    arm_span: length_property("arm_span_m", "Arm Span",
                              "Wrist-to-wrist distance in a T-pose (0: measured on the T-pose with Automatic or "
                              "T-Pose calibration, else from proportions)", *LENGTH_RANGES["arm_span"])
    sole_m: FloatProperty(default=0.03, min=LENGTH_RANGES["sole"][0], max=LENGTH_RANGES["sole"][1],
                          options={'HIDDEN'})
    sole: length_property("sole_m", "Shoe Soles",
                          "Thickness of the performer's shoe soles: the feet stand this far above the "
                          "floor, and the height measured from the headset is the barefoot one (0 = barefoot)",
                          *LENGTH_RANGES["sole"])
    floor_mode: EnumProperty(
        name="Floor", default='ZERO',
        items=[('ZERO', "At Zero", "The recording's height 0 is the floor (room-scale VR: OpenXR stage, "
                "SteamVR standing); a head standing near 0 (an origin at eye level) gets its floor under "
                "the performer: the typed height, else the T-pose's arm span, else 1.75 m"),
               ('OFFSET', "At Height", "The floor is at Floor Height in the recording"),
               ('PERFORMER', "Under Performer", "The floor is put under a performer of the typed Height "
                "standing in the take (an origin at eye level or on a desk)")],
        description="Where the recording's floor is; the solve moves it to Blender's ground (z = 0)")
    floor_height_m: FloatProperty(default=0.0, options={'HIDDEN'})
    floor_height: length_property("floor_height_m", "Floor Height",
                                  "Height of the recording's floor on its vertical axis")

    model: EnumProperty(
        name="Pose Model", default='AUTO',
        items=[('AUTO', "Automatic", "The shipped network for the recording's trackers (head and hands; "
                "+ pelvis; + pelvis and feet), per stretch when a tracker is lost for long"),
               ('HEAD_HANDS', "Head and Hands", "The three-tracker network, whatever else is tracked "
                "(a pelvis or foot tracker still drives the pelvis or ankle)"),
               ('PELVIS', "Head, Hands and Pelvis", "The four-tracker network"),
               ('SIX', "Six Trackers", "The network for head, hands, pelvis and feet"),
               ('FILE', "Model File", "A network you trained (.onnx)")])
    overlap: EnumProperty(
        name="Overlap", default='2',
        items=[('2', "2 Windows", "Each frame is seen by two network windows (fastest)"),
               ('3', "3 Windows", "Each frame is seen by three network windows: a little more accurate, "
                "1.5 times the network time"),
               ('4', "4 Windows", "Each frame is seen by four network windows: twice the network time")],
        description="How many network windows see each frame; more average more views of it")
    posture: EnumProperty(
        name="Posture", default='STANDING',
        items=[('STANDING', "Standing", "The performer stands, walks, crouches or lies (the network's legs)"),
               ('SEATED', "Seated", "The performer sits on a chair: thighs forward, shins upright, feet on the "
                "floor; the stature from the height, a standing T-pose or the seated head")],
        description="Whether the performer stands or sits on a chair")
    teleports: EnumProperty(
        name="Teleports", default='KEEP',
        items=[('KEEP', "Keep", "Teleports and snap turns of the app (the tracking space jumping) are "
                "solved as one motion and put back: the body jumps where the recording does, its pose "
                "unbroken"),
               ('REMOVE', "Remove", "Teleports and snap turns are left out: the body's path is continuous"),
               ('IGNORE', "Ignore", "Solve the recording as it stands (a jump then tears the pose apart "
                "around it)")],
        description="What to do where the app moved the tracking space (teleports, snap turns)")
    model_file: StringProperty(name="Model File", subtype='FILE_PATH', default="",
                               description="A pose network trained with blender_manikin.training (.onnx)")
    offsets_preset: EnumProperty(name="Offsets", items=_preset_items,
                                 description="Device-to-joint offsets preset")
    offsets_text: PointerProperty(
        name="Edited Offsets", type=bpy.types.Text,
        description="Text block with offsets JSON (made by Edit Offsets) used instead of the preset")

    use_scene_range: BoolProperty(name="Scene Frame Range", default=True,
                                  description="Scene objects: sample the scene's frame range; recordings: "
                                              "start on the scene's first frame (off: from Start)")
    frame_start: IntProperty(name="Start", default=1, description="First frame of the solve")
    frame_end: IntProperty(name="End", default=250,
                           description="Last frame (scene objects and keypoint objects; recordings when "
                                       "Limit is on)")
    limit_frames: BoolProperty(name="Limit", default=False,
                               description="Recordings: stop at the End frame")
    use_trim_start: BoolProperty(name="Trim Start", default=False,
                                 description="Recordings: solve from this time on (the T-pose is still "
                                             "looked for in the whole take)")
    trim_start: FloatProperty(name="From", default=0.0, min=0.0, unit='TIME_ABSOLUTE', subtype='TIME_ABSOLUTE',
                              description="Seconds from the recording's first sample")
    use_trim_end: BoolProperty(name="Trim End", default=False,
                               description="Recordings: solve up to this time")
    trim_end: FloatProperty(name="To", default=10.0, min=0.0, unit='TIME_ABSOLUTE', subtype='TIME_ABSOLUTE',
                            description="Seconds from the recording's first sample")

    live_rig: BoolProperty(name="Live Swivel Rig", default=True,
                           description="Elbows and knees follow the swivel properties and the "
                                       "hand/foot controls live (constraints + drivers); off: plain FK keys")
    create_trackers: BoolProperty(name="Tracker Empties", default=True,
                                  description="Also create keyed empties at the device targets")
    body_mesh: BoolProperty(name="Mannequin", default=True,
                            description="Give the solved armature a mannequin mesh skinned to its bones, "
                                        "to judge contacts, reach and volume (exported with the FBX)")
    mark_problems: BoolProperty(name="Mark Problems", default=True,
                                description="Timeline markers (\"MANIKIN: ...\") where the solve is worth a look: a "
                                            "hand or foot out of reach, a swivel at its limit, a device lost, "
                                            "a teleport; a new solve replaces the ones in its frame range")
    set_scene_range: BoolProperty(name="Set Scene Range", default=True,
                                  description="Set the scene frame range to the solved animation")
    reuse_armature: BoolProperty(name="Reuse Armature", default=True,
                                 description="Write the new action to the armature of the last solve "
                                 "when its body matches (else a new armature is created)")
    armature: PointerProperty(name="Armature", type=bpy.types.Object, poll=_armature_poll,
                              description="Armature of the last solve")
    last_report: StringProperty(name="Last Solve", default="")

    retarget_target: PointerProperty(name="Character", type=bpy.types.Object, poll=_character_poll,
                                     update=_retarget_inputs_changed,
                                     description="The character's armature the solved motion goes onto")
    retarget_map: EnumProperty(name="Bone Map", items=_bone_map_items(), default='AUTO',
                               update=_retarget_inputs_changed,
                               description="Which of the character's bones each joint drives")
    retarget_map_file: StringProperty(name="Map File", subtype='FILE_PATH', default="",
                                      update=_retarget_inputs_changed,
                                      description="A saved bone map (JSON: joint -> bone)")
    retarget_bone_map: CollectionProperty(type=MANIKIN_BoneMapItem, name="Bone Map Rows",
                                          description="The bone map editor: each joint and the character's "
                                                      "bone that follows it")
    retarget_bone_map_index: IntProperty(name="Active Row", default=0, min=0)
    retarget_bone_map_name: StringProperty(name="Map Name", default="edited",
                                           description="The bone map's name (saved in its JSON)")
    retarget_bone_map_edited: BoolProperty(name="Edited", default=False,
                                           description="Rows were changed by hand since they were loaded "
                                                       "(they are then only replaced by Load Map)")
    retarget_bone_map_source: StringProperty(name="Loaded From", default="",
                                             description="The map the rows were loaded from")
    export_fbx_preset: EnumProperty(name="FBX Preset", items=fbx_preset_items(), default='BLENDER',
                                    description="Axes, units and bones of the exported FBX, for the "
                                                "application that reads it")
    export_format: EnumProperty(name="Format", items=export_format_items(), default='FBX',
                                description="The file Export and Export Each Take write")
    retarget_root: EnumProperty(
        name="Root Motion", default='SCALED',
        items=[('SCALED', "Scaled", "The hips travel as the performer's, scaled by the ratio of leg lengths"),
               ('IN_PLACE', "In Place", "No horizontal travel; the height changes scaled"),
               ('AS_IS', "As Is", "The performer's travel, unscaled")])
    retarget_keep_ends: BoolProperty(name="Keep Hands and Feet on Targets", default=False,
                                     description="Solve the character's arms and legs again on its own limb "
                                                 "lengths, keeping the swivel, so its hands and feet land where "
                                                 "the performer's were (with Scaled or In Place root motion: the "
                                                 "feet scaled like the hips, the hands from the character's own "
                                                 "shoulders by its arm length)")
    retarget_live_swivel: BoolProperty(name="Live Swivel on Character", default=True,
                                       description="With Keep Hands and Feet on Targets: the character gets the "
                                                   "keyed swivel properties and a live rig, so editing a swivel "
                                                   "turns its elbow / knee while the hand / foot stays (Bake "
                                                   "Character to FK for plain keys)")


def device_source(settings, device):
    return getattr(settings, device)


def config_from_settings(context):
    """A :class:`~.solve_job.SolveConfig` from ``context.scene.manikin``."""
    from .solve_job import SolveConfig, SolveError
    from .writer import scene_fps
    scene = context.scene
    s = scene.manikin
    cfg = SolveConfig()
    cfg.source = s.source
    cfg.filepath = bpy.path.abspath(s.filepath) if s.filepath else ""
    if s.source == 'KEYPOINTS':
        cfg.filepath = bpy.path.abspath(s.keypoint_path) if s.keypoint_path else ""
        if s.keypoint_from == 'FILE' and cfg.filepath:
            from ..core.io_keypoints import frames_folder_of
            cfg.filepath = frames_folder_of(cfg.filepath) or cfg.filepath   # one frame's file: its folder
        if s.keypoint_from == 'OBJECTS':
            if s.keypoint_collection is None:
                raise SolveError("choose the collection of the keypoint objects")
            cfg.filepath = ""
            cfg.keypoint_collection = s.keypoint_collection.name
            cfg.scene_frames = None if s.use_scene_range else (s.frame_start, s.frame_end)
        elif s.keypoint_from == 'ARMATURE':
            if s.keypoint_armature is None:
                raise SolveError("choose the animated armature whose bones give the keypoints")
            cfg.filepath = ""
            cfg.keypoint_armature = s.keypoint_armature.name
            cfg.keypoint_bone_map = s.keypoint_bone_map.lower()
            cfg.keypoint_map_file = bpy.path.abspath(s.keypoint_map_file) if s.keypoint_map_file else None
            cfg.scene_frames = None if s.use_scene_range else (s.frame_start, s.frame_end)
        cfg.keypoint_floor = (('keep' if s.keypoint_from == 'ARMATURE' else 'feet') if s.keypoint_floor == 'AUTO'
                              else s.keypoint_floor.lower())
        cfg.keypoint_layout = None if s.keypoint_layout == 'AUTO' else s.keypoint_layout.lower()
        cfg.up = None if s.keypoint_up == 'AUTO' else s.keypoint_up.lower()
        if s.keypoint_from == 'FILE' and s.keypoint_subject_file:
            cfg.subject_params = bpy.path.abspath(s.keypoint_subject_file)
        if s.keypoint_from == 'FILE':
            cfg.person = s.keypoint_person.strip() or "all"
        cfg.rate = float(s.keypoint_rate) if s.use_keypoint_rate else None
        cfg.ik = s.ik.lower()
        cfg.despike = bool(s.despike)
    cfg.fix_sides = bool(s.fix_sides)
    cfg.smoothing = "auto" if s.smoothing_mode == 'AUTO' else float(s.smoothing)
    cfg.layout = bpy.path.abspath(s.layout_file) if s.layout_file else None
    cfg.axes = None if s.axes == 'AUTO' else s.axes.lower()
    units = s.keypoint_units if s.source == 'KEYPOINTS' else s.units
    cfg.units = None if units == 'AUTO' else units.lower()
    cfg.fps = scene_fps(scene) if s.use_scene_fps else float(s.fps)
    cfg.calibration = s.calibration
    cfg.tpose_time = float(s.tpose_time)
    cfg.calibration_take = bpy.path.abspath(s.calibration_take) if s.calibration_take and s.source != 'KEYPOINTS' \
        else None
    trackers = s.source != 'KEYPOINTS'
    if s.use_height or (trackers and (s.calibration == 'MEASURE' or s.floor_mode == 'PERFORMER')):
        cfg.height = float(s.height_m)
    cfg.arm_span = float(s.arm_span_m) if s.arm_span_m > 0 else None
    cfg.sole = float(s.sole_m)
    if trackers:
        cfg.floor = {'ZERO': 0.0, 'OFFSET': float(s.floor_height_m), 'PERFORMER': FLOOR_FROM_HEIGHT}[s.floor_mode]
    if s.offsets_text is not None:
        try:
            cfg.offsets = json.loads(s.offsets_text.as_string())
        except json.JSONDecodeError as exc:
            raise SolveError(f"offsets text {s.offsets_text.name!r}, line {exc.lineno}: "
                             f"not valid JSON ({exc.msg})") from None
    else:
        cfg.offsets = s.offsets_preset or "none"
    if s.model == 'FILE':
        if not s.model_file:
            raise SolveError("Pose Model is 'Model File' but no file is chosen")
        cfg.model = bpy.path.abspath(s.model_file)
    else:
        cfg.model = s.model.lower()
    cfg.overlap = int(s.overlap)
    cfg.teleports = s.teleports.lower()
    cfg.posture = s.posture.lower()
    cfg.create_trackers = s.create_trackers
    cfg.body_mesh = s.body_mesh
    cfg.live_rig = s.live_rig
    cfg.set_scene_range = s.set_scene_range
    cfg.mark_problems = s.mark_problems
    cfg.reuse_armature = s.armature if (s.reuse_armature and s.armature is not None
                                        and s.armature.name in scene.objects) else None
    if s.source == 'SCENE':
        cfg.scene_sources = {}
        for d in DEVICES:
            src = device_source(s, d)
            if src.object is not None:
                cfg.scene_sources[d] = (src.object.name, src.bone)
        cfg.scene_frames = ((scene.frame_start, scene.frame_end) if s.use_scene_range
                            else (s.frame_start, s.frame_end))
        cfg.fps = scene_fps(scene)      # scene sources are sampled on scene frames
    else:
        cfg.frame_start = s.frame_start if not s.use_scene_range else scene.frame_start
        cfg.start = float(s.trim_start) if s.use_trim_start else None
        cfg.end = float(s.trim_end) if s.use_trim_end else None
        if s.limit_frames:
            cfg.max_frames = max(1, s.frame_end - cfg.frame_start + 1)
    return cfg


CLASSES = (MANIKIN_DeviceSource, MANIKIN_BoneMapItem, MANIKIN_Settings)
