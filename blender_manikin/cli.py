"""Headless batch conversion: tracker recordings → .blend / .fbx / .glb / .bvh / .json / .npz.

Two ways to run it (the same code)::

    blender -b --python <add-on dir>/cli.py -- solve INPUT... --out DIR [options]
    python -m blender_manikin solve INPUT... --out DIR [options]     # with the bpy module, or
                                                                     # without it for json/bvh

INPUT is a recording (any format of :mod:`blender_manikin.core.formats`: ``.csv`` native
or wide layout, ``.bsor`` Beat Saber replay, ``.xror`` XROR), 3D keypoints (a FreeMoCap
recording folder, ``.npy`` / ``.npz`` arrays, a keypoint CSV, a keypoint ``.json`` or a folder of per-frame
JSON keypoints (EasyMocap, OpenPose 3-D), a ``.trc`` / ``.c3d`` of markers; solved by HybrIK IK, see
:mod:`blender_manikin.core.keypoint_solve`) or a folder (its recordings, sorted).  For every
input the scene is reset to an empty factory scene, the recording is solved and
``DIR/STEM.<ext>`` is written for each format (inputs that share a name, ``take.csv`` in two
folders, are told apart as ``convert`` does: ``take-<hash>.<ext>``; an input written into DIR
by an earlier run keeps the name it had there, whatever else shares the batch); a file already there is
replaced only when it is this tool's unchanged output of an earlier run, else the input stops
with an error naming it (``--overwrite`` replaces it; :mod:`.core.output_guard`).  One line per
converted input on stdout (``OK INPUT -> outputs (summary)``); problems on stderr as ``ERROR INPUT: message``; a bad
file does not stop the others; the last stderr line counts converted and failed inputs.  Exit
status 0 only when every input converted, 1 when any failed, 2 for usage errors, 130 when Ctrl-C
stopped the batch, 143 for SIGTERM (the inputs after it not started, no output or temporary file
left half-written).

Options of ``solve`` (they mirror the panel; ``--help`` has them all):

--axes NAME                   override the file's axes metadata: openxr, unity,
                              blender or unreal
--units m|cm|mm               override the file's units metadata
--fps N                       solve/scene frame rate (default 30)
--calibration-time SECONDS    T-pose at that time (seconds after the first sample)
--calibration-take FILE       trackers: calibrate on this recording's T-pose (the
                              session's calibration take) instead of the input's own
--height METRES               performer's stature (with --calibration-time it
                              overrides the measured stature; alone it is the
                              body measurement)
--arm-span METRES             wrist-to-wrist span, kept as typed (default: the T-pose's)
--sole METRES                 the performer's shoe soles (default 0.03; 0 barefoot)
--floor METRES|height         trackers: the recording's floor height (default 0: a head
                              standing near 0, an origin at eye level, gets its floor
                              under the performer), or 'height': under the --height
                              performer standing in the take; moved to 0
--offsets auto|none|PRESET|FILE  device offsets: auto (the file's metadata or its
                              format's default; a CSV that does not say: none, or
                              openxr_generic where the take shows a headset), a preset
                              name or a JSON file
--layout FILE.json            the columns, time, units, axes and Euler order of
                              wide-layout CSV and JSON inputs (default: detected)
--layout KEYPOINTS            the layout of keypoint inputs: mediapipe33, coco17,
                              h36m17, smpl22, smpl24, body25 (default: detected)
--rate HZ                     samples per second of a wide-layout CSV, JSON or
                              keypoints with no times
--up +x|-x|+y|-y|+z|-z        keypoints: the file's up axis (default: detected)
--smoothing auto|SECONDS      trackers and keypoints: auto (default: each device's or point's
                              filter from its measured noise; clean ones are left as they
                              are) or one Savitzky-Golay window in seconds (0: off)
--overlap 2|3|4               network windows seeing each frame: 2 (default, fastest), 3 or 4
                              (a little more accurate at 1.5 and 2 times the network time)
--posture standing|seated     trackers: seated sits the legs on a chair, feet on the floor
                              (the stature from --height, a standing T-pose or the seated head)
--start SECONDS, --end SECONDS  solve only this part of the take (seconds from its first
                              sample; a tracker take is still calibrated on the whole)
--teleports keep|remove|ignore  trackers: an app's teleports and snap turns (the tracking
                              space jumping) are solved as one motion and put back on the
                              body (keep, default), left out (remove: a continuous path),
                              or not looked for (ignore)
--ik adaptive|naive           keypoints: HybrIK adaptive (default) or naive IK
--keep-sides                  keep left/right labels as read (default: keypoints: swap
                              back a limb the detector labelled as the other side;
                              trackers: swap back controllers held in the other hands
                              and foot trackers worn on the other feet)
--keep-spikes                 keypoints: keep every sample (default: remove samples
                              30 cm or more off their point's local median)
--keypoint-floor feet|keep    keypoints: feet (default) stands the body on the floor
                              found under the feet, at z = 0; keep leaves the heights as given
--subject-params FILE|none    keypoints: a Vicon subject parameter file (.mp / .vsk) for a
                              Plug-in Gait .trc / .c3d: knee, ankle, elbow widths, height
                              (default: <Subject>.mp / .vsk beside the file, or the folder's
                              only .mp; none: use none)
--person all|N|LABEL          keypoints with several people: all (default: each to its
                              own outputs, <name>_p<label>) or one person's label or index
--person-axis 0|1             keypoints: a 4-D array's people axis (default: told)
--mapping FILE.json           keypoints: a CSV's column names for the layout's points
--save-layout FILE.json       write the layout detected in the first wide CSV or JSON
--format blend,fbx,glb,bvh,json,npz  one or several (default blend,fbx,json); without
                              blend, fbx and glb, the numpy core writes them without Blender
--bvh-units cm|m              BVH length unit (default cm)
--fbx-preset blender|unity|unreal  FBX axes, units and bones for the engine that reads it
                              (default blender: as before; see blender/fbx_presets.py)
                              (glb, glTF binary, has no preset: Y up, metres, deforming
                              bones, every frame from 0 s; see blender/gltf_export.py)
--trackers                    also create (and export) keyed tracker empties
--retarget FILE.blend[:OBJECT]  also put the motion onto this character (appended); blend and
                              fbx / glb then carry it (--bone-map auto|PRESET|FILE.json,
                              --root-motion scaled|in_place|as_is, --keep-ends,
                              --live-swivel|--no-live-swivel: swivel rig on the
                              character, default with --keep-ends)
--no-live-rig                 plain FK keys only (no live swivel rig)
--no-marks                    no timeline markers where the solve is worth a look (.blend)
--no-mannequin                no mannequin mesh on the solved armature (.blend, .fbx, .glb)
--overwrite                   replace files in DIR that are in the way (the user's, or edited)
--dry-run                     print ``INPUT -> OUTPUTS`` per input and write nothing

``convert INPUT... --out DIR`` converts many recordings on Dask (the same solve options, plus
``--scheduler`` and ``--workers``; :mod:`blender_manikin.core.convert`).

When run by a Blender binary as a plain script, this file puts its parent
directory on ``sys.path`` and imports the package, so it works from any
installed location.
"""
from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import signal
import sys
import tempfile

DEFAULT_FORMATS = ("blend", "fbx", "json")
if __package__:   # run as a plain script (blender --python cli.py), _script_main imports the package
    from .core import formats as _formats  # the format registry (no bpy)

    FORMATS = _formats.writer_names()
    #: formats written by Blender (need bpy); the others are written by the numpy core
    BLENDER_FORMATS = tuple(n for n, f in _formats.WRITERS.items() if f.needs_blender)


def _add_solve_options(s):
    """The options every solve takes (the panel's settings)."""
    from .core.recording import AXES
    from .core.skeleton import LENGTH_RANGES
    s.add_argument("--axes", choices=AXES, default=None,
                   help="axes of the input (default: the file's metadata; OpenXR for CSV, Unity for .bsor)")
    s.add_argument("--units", choices=("m", "cm", "mm"), default=None,
                   help="position units of the input (default: the file's metadata, else metres)")
    s.add_argument("--fps", type=float, default=30.0, help="frame rate of the output animation (default 30)")
    s.add_argument("--calibration-time", type=float, default=None, metavar="SECONDS",
                   help="calibrate on the T-pose this many seconds after the first sample "
                        "(default: the most T-pose-like moment, else the standing head height)")
    s.add_argument("--calibration-take", default=None, metavar="FILE",
                   help="trackers: calibrate on the T-pose of this recording (the session's calibration take: "
                        "the same performer and trackers) instead of the input's own; --calibration-time is "
                        "then a time in it")
    s.add_argument("--height", type=_metres_arg(*LENGTH_RANGES["height"]), default=None, metavar="METRES",
                   help="performer's stature (0.5-2.8)")
    s.add_argument("--arm-span", type=_metres_arg(*LENGTH_RANGES["arm_span"]), default=None, metavar="METRES",
                   help="wrist-to-wrist distance in a T-pose (0-3; kept as typed; 0 or left out: measured on the "
                        "take's T-pose, else from the proportions)")
    s.add_argument("--sole", type=_metres_arg(*LENGTH_RANGES["sole"]), default=None, metavar="METRES",
                   help="thickness of the performer's shoe soles: the feet stand this far above the floor "
                        "(0-0.2, default 0.03; 0 barefoot)")
    s.add_argument("--floor", type=_floor_arg, default=0.0, metavar="METRES|height",
                   help="trackers: where the recording's floor is, metres on its vertical axis (default 0; a "
                        "head standing within 0.5 m of 0, an origin at eye level, gets its floor under the "
                        "performer: --height, else the T-pose's arm span, else 1.75 m), or 'height': under the "
                        "performer of --height standing in the take (an origin on a desk); moved to 0")
    s.add_argument("--offsets", default="auto", metavar="auto|none|PRESET|FILE",
                   help="device-to-joint offsets: a preset name, a JSON file, or auto (default: the "
                        "recording's '# offsets:' metadata, a Beat Saber replay's own saber offsets or the game's "
                        "defaults for its version and controllers (beat_saber, beat_saber_xr_touch, ...), "
                        "openxr_generic for other .xror, else none, or openxr_generic where the take shows a "
                        "headset: its T-pose, or a head named hmd, Main Camera, ...)")
    s.add_argument("--bvh-units", choices=("cm", "m"), default="cm", help="BVH length unit (default cm)")
    s.add_argument("--model", default="auto", metavar="auto|head_hands|pelvis|six|FILE.onnx",
                   help="trackers: the pose network (keypoints are solved without one): auto (default: the "
                        "shipped model for the recording's trackers, "
                        "head and hands / + pelvis / + pelvis and feet, per stretch when a tracker is lost "
                        "for long), a shipped model's name, or a model you trained")
    from .core.pipeline import DEFAULT_OVERLAP, OVERLAP_CHOICES
    s.add_argument("--overlap", type=int, choices=OVERLAP_CHOICES, default=DEFAULT_OVERLAP,
                   help="network windows that see each frame: 2 (default, fastest), 3 or 4 (a little "
                        "more accurate at 1.5 and 2 times the network time)")
    from .core.seated import POSTURES
    s.add_argument("--posture", choices=POSTURES, default="standing",
                   help="trackers: standing (default) or seated: the legs sit on a chair, feet on the floor "
                        "(the stature from --height, a standing T-pose, or the seated head height)")
    s.add_argument("--start", type=_seconds_arg, default=None, metavar="SECONDS",
                   help="solve from this time on (seconds from the recording's first sample; a tracker take "
                        "is still calibrated on its T-pose wherever it is)")
    s.add_argument("--end", type=_seconds_arg, default=None, metavar="SECONDS",
                   help="solve up to this time (seconds from the recording's first sample)")
    from .core.teleports import TELEPORT_CHOICES
    s.add_argument("--teleports", choices=TELEPORT_CHOICES, default="keep",
                   help="trackers: an app's teleports and snap turns are solved as one motion and put back "
                        "on the body (keep, default), left out (remove: the path continuous), or not looked "
                        "for (ignore)")
    s.add_argument("--layout", default=None, metavar="FILE.json|KEYPOINTS",
                   help="the columns, time, units and axes of wide-layout CSV and JSON inputs (default: detected); "
                        "or the layout of keypoint inputs: " + "|".join(_keypoint_layouts()))
    s.add_argument("--rate", type=float, default=None, metavar="HZ",
                   help="samples per second of wide-layout CSV, JSON or keypoint inputs without times")
    s.add_argument("--up", default=None, choices=("+x", "-x", "+y", "-y", "+z", "-z"),
                   help="keypoints: the file's up axis (default: told from the body)")
    s.add_argument("--smoothing", type=_smoothing_arg, default="auto", metavar="auto|SECONDS",
                   help="trackers and keypoints: 'auto' (default: each device or point gets the "
                        "Savitzky-Golay filter its measured noise calls for; clean ones are left as they are) "
                        "or one window in seconds for all (0: off)")
    s.add_argument("--ik", choices=("adaptive", "naive"), default=None,
                   help="keypoints: HybrIK adaptive (default) or naive twist-and-swing IK")
    s.add_argument("--keep-sides", action="store_true",
                   help="keep the left/right labels as read (default: keypoints: a leg's or arm's points "
                        "the detector gave the other side's labels for a few frames get their own back; "
                        "trackers: controllers held in the other hands, or foot trackers worn on the other feet, "
                        "for the whole take are swapped back)")
    s.add_argument("--keep-spikes", action="store_true",
                   help="keypoints: keep every sample as read (default: samples 30 cm or more off their "
                        "point's local median, a detector's misplacements, are removed and bridged)")
    s.add_argument("--keypoint-floor", default="feet", choices=("feet", "keep"),
                   help="keypoints: feet (default) moves the floor found under the feet to z = 0, the body "
                        "on its --sole; keep leaves the joints at the heights given (a source whose floor "
                        "is the scene's)")
    s.add_argument("--subject-params", default=None, metavar="FILE",
                   help="keypoints: a Vicon subject parameter file (.mp or .vsk) for a Plug-in Gait .trc / .c3d: the "
                        "subject's knee, ankle and elbow widths place the joint centres from lateral markers, "
                        "its Height is the stature unless --height is given (default: <Subject>.mp / .vsk "
                        "beside the file, or the folder's only .mp; 'none': none)")
    s.add_argument("--person", default="all", metavar="all|N|LABEL",
                   help="keypoints with several people (a 4-D array, a CSV with a person column): all "
                        "(default: each solved to its own outputs, <name>_p<label>) or one person's label "
                        "or 0-based index")
    s.add_argument("--person-axis", type=int, choices=(0, 1), default=None,
                   help="keypoints: a 4-D array's people axis, 0 (people, frames, points, 3|4) or 1 "
                        "(frames, people, points, 3|4) (default: the .npz's person_axis, else the "
                        "axis much shorter than the other)")
    s.add_argument("--mapping", default=None, metavar="FILE.json",
                   help="keypoints: a CSV's columns for the layout's points "
                        '({"layout": "coco17", "columns": {"nose": "Nose", ...}})')
    s.add_argument("--save-layout", default=None, metavar="FILE.json",
                   help="write the layout detected in the first wide-layout CSV or JSON input, for --layout")


def _bone_map_presets():
    from .core.bone_maps import PRESETS
    return tuple(PRESETS)


def _fbx_presets():
    from .blender.fbx_presets import PRESET_NAMES     # plain data: no bpy needed to list them
    return PRESET_NAMES


def append_character(spec):
    """The armature object named by ``spec`` (``FILE.blend`` or ``FILE.blend:OBJECT``), appended
    into the current file with its children (meshes); ``ValueError`` naming the problem."""
    import bpy
    path, _, name = str(spec).partition(".blend:")
    path = path + ".blend" if name or not path.endswith(".blend") else path
    if not os.path.isfile(path):
        raise ValueError(f"--retarget: no such file {path!r}")
    with bpy.data.libraries.load(path, link=False) as (src, dst):
        dst.objects = list(src.objects)
    objs = [o for o in dst.objects if o is not None]
    arms = [o for o in objs if o.type == 'ARMATURE' and (not name or o.name == name)]
    if len(arms) != 1:
        have = ", ".join(sorted(o.name for o in objs if o.type == 'ARMATURE')) or "none"
        for o in objs:
            bpy.data.objects.remove(o)
        what = f"no armature named {name!r}" if name else "name the armature, FILE.blend:OBJECT"
        raise ValueError(f"--retarget {spec}: {what} (armatures in the file: {have})")
    arm = arms[0]
    keep = {arm} | {o for o in objs if o.parent == arm}
    coll = bpy.context.scene.collection
    for o in objs:
        if o in keep:
            coll.objects.link(o)
        else:
            bpy.data.objects.remove(o)
    return arm


def _metres_arg(lo, hi):
    """argparse type of a length option: metres from ``lo`` to ``hi``; a value over ``hi`` that
    would fit in centimetres is refused with the metres it means (``--height 175``: 1.75)."""
    def parse(text):
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number of metres") from None
        if not lo <= v <= hi:
            # a whole number of centimetres typed for metres (175, 3); 0.3 for a 0.2 m range is no such slip
            hint = f" (metres: {v / 100:g} for {v:g} cm?)" if lo <= v / 100 <= hi and v > hi and v >= 1 else ""
            raise argparse.ArgumentTypeError(f"{text!r}: expected metres from {lo:g} to {hi:g}{hint}")
        return v
    parse.__name__ = "metres"
    return parse


def _seconds_arg(text):
    """argparse type of ``--start`` / ``--end``: seconds >= 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not (v >= 0 and v != float("inf")):
        raise argparse.ArgumentTypeError(f"{text!r}: expected seconds >= 0")
    return v


def _workers_arg(text):
    """argparse type of ``--workers``: a whole number >= 1."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected 1 or more workers")
    return v


def _smoothing_arg(text):
    """argparse type of ``--smoothing``: ``auto`` or seconds >= 0."""
    from .core.smoothing import parse_smoothing
    from .core.solve import SolveError
    try:
        return parse_smoothing(text)
    except SolveError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _floor_arg(text):
    """argparse type of ``--floor``: metres or ``height``."""
    from .core.solve import SolveError, parse_floor
    try:
        return parse_floor(text)
    except SolveError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _keypoint_layouts():
    from .core.keypoint_layouts import LAYOUTS
    return tuple(LAYOUTS)


OVERWRITE_HELP = ("replace files in --out that are in the way (default: only this tool's own outputs of an "
                  "earlier run, unchanged since, are replaced; an input whose output would replace a file "
                  "made or edited since stops with an error naming it)")
DRY_RUN_HELP = ("print INPUT -> OUTPUTS for each input (the names a run would write) and write nothing, not "
                "even --out; an input the output guard would refuse is an ERROR line and the exit status 1")


def build_parser():
    p = argparse.ArgumentParser(
        prog="blender_manikin",
        description="Convert VR tracker recordings to full-body animation (MANIKIN).")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("solve", help="solve recordings and write animation files")
    s.add_argument("inputs", nargs="+", metavar="INPUT", type=os.path.expanduser, help="recording files or folders")
    s.add_argument("--out", required=True, metavar="DIR", type=os.path.expanduser,
                   help="output folder (created if missing)")
    _add_solve_options(s)
    s.add_argument("--format", default=",".join(DEFAULT_FORMATS), metavar="LIST",
                   help="comma-separated: " + ",".join(FORMATS))
    s.add_argument("--fbx-preset", default="blender", type=str.lower, choices=_fbx_presets(),
                   help="FBX export settings: blender (default: Blender's axes and units), unity (Y up, "
                        "metres, deforming bones) or unreal (Z up, centimetres with the skeleton at scale 1, "
                        "deforming bones)")
    s.add_argument("--trackers", action="store_true", help="create keyed tracker empties")
    s.add_argument("--retarget", default=None, metavar="FILE.blend[:OBJECT]",
                   help="also put the motion onto this character (an armature appended from a .blend; "
                        "OBJECT: its name when the file holds several); blend/fbx/glb then carry it")
    s.add_argument("--bone-map", default="auto", metavar="PRESET|FILE.json",
                   help="the character's bone map: auto (guessed), a preset (" + ",".join(_bone_map_presets())
                        + ") or a saved map")
    s.add_argument("--root-motion", choices=("scaled", "in_place", "as_is"), default="scaled",
                   help="retarget: the hips' travel scaled by the leg lengths' ratio (default), in place, as is")
    s.add_argument("--keep-ends", action="store_true",
                   help="retarget: solve the character's limbs again so its hands and feet land where the "
                        "performer's were")
    s.add_argument("--live-swivel", dest="live_swivel", action="store_true", default=None,
                   help="retarget: give the character the keyed swivel properties and a live rig (elbows / "
                        "knees follow the swivel, hands / feet stay; default with --keep-ends)")
    s.add_argument("--no-live-swivel", dest="live_swivel", action="store_false",
                   help="retarget: plain keys on the character, no live swivel rig")
    s.add_argument("--no-marks", dest="marks", action="store_false",
                   help="no timeline markers ('MANIKIN: ...') where the solve is worth a look")
    s.add_argument("--no-mannequin", dest="mannequin", action="store_false",
                   help="no mannequin mesh on the solved armature (blend, fbx, glb)")
    s.add_argument("--no-live-rig", dest="live_rig", action="store_false",
                   help="write plain FK keys only (default: the live swivel rig, whose elbows and knees "
                        "follow the swivel properties)")
    s.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    s.add_argument("--dry-run", action="store_true", help=DRY_RUN_HELP)
    c = sub.add_parser("convert", help="convert many recordings in parallel on Dask, without Blender")
    c.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="recording files, folders (recursive), globs, or manifest files (.txt/.lst/.jsonl)")
    c.add_argument("--out", required=True, metavar="DIR", type=os.path.expanduser,
                   help="output folder; DIR/manifest.jsonl records each input")
    _add_solve_options(c)
    c.add_argument("--format", default="json", metavar="LIST",
                   help="comma-separated: " + ",".join(n for n in FORMATS if n not in BLENDER_FORMATS))
    c.add_argument("--scheduler", default="local", metavar="local|ADDRESS",
                   help="a Dask scheduler address (tcp://host:8786), or local (default: a LocalCluster)")
    c.add_argument("--workers", type=_workers_arg, default=None, metavar="N",
                   help="LocalCluster worker processes, 1 or more (default: one per core)")
    c.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar on stderr")
    c.add_argument("--overwrite", action="store_true", help=OVERWRITE_HELP)
    c.add_argument("--dry-run", action="store_true", help=DRY_RUN_HELP.replace(
        "INPUT -> OUTPUTS for each input", "INPUT -> OUTPUTS for each input (skipped: converted before)"))
    return p


def parse_formats(text):
    fmts = [f.strip().lower().lstrip(".") for f in str(text).split(",") if f.strip()]
    bad = [f for f in fmts if f not in FORMATS]
    if bad or not fmts:
        raise ValueError(f"unknown format(s) {', '.join(bad) or '(none)'}: choose from {', '.join(FORMATS)}")
    return tuple(dict.fromkeys(fmts))


def _holds_recordings(folder):
    """Whether ``folder`` (not its sub-folders) holds a recording or is a keypoint input itself
    (a FreeMoCap recording, a folder of per-frame JSON keypoints)."""
    from .core.io_keypoints import freemocap_body_file, json_frames_folder
    try:
        names = os.listdir(folder)
    except OSError:
        return True                     # named, so an unreadable folder is not passed over unseen
    return bool(freemocap_body_file(folder) or json_frames_folder(folder)
                or any(os.path.isfile(os.path.join(folder, n)) and _formats.is_recording_file(os.path.join(folder, n))
                       for n in names))


def expand_inputs(inputs, out=None):
    """Files of ``inputs`` with folders expanded to their recordings (sorted), except FreeMoCap
    recording folders and folders of per-frame JSON keypoints, which are one input each (an
    output folder holding a ``keypoints3d`` folder is one, and its own recordings are inputs too).  Order
    kept; a file given twice (again, in a folder also given, or through a symbolic link) is
    solved once, under its first name.  A folder's sub-folders are not searched: they are named
    on stderr (but not ``out``, the output folder), so a nested take is not passed over unseen;
    a symbolic link with a recording's extension whose target is gone (or that loops) is listed,
    and its solve says so."""
    from .core.io_keypoints import freemocap_body_file, json_frames_folder
    files = []
    for item in inputs:
        frames = json_frames_folder(item)
        if os.path.isdir(item) and (freemocap_body_file(item) or (
                frames is not None and os.path.normpath(frames) == os.path.normpath(item))):
            # a FreeMoCap recording, a folder of per-frame JSON keypoints (EasyMocap, OpenPose): one input
            files.append(item.rstrip("/\\") or item)
        elif os.path.isdir(item):
            if frames is not None:      # an output folder holding keypoints3d/: that input, and its own recordings
                files.append(item.rstrip("/\\") or item)
            # a link with a recording's extension whose target is gone or that loops is kept, so
            # the solve says so (recording.missing_file) instead of leaving the take out unseen
            found = sorted(p for p in (os.path.join(item, n) for n in os.listdir(item))
                           if (os.path.isfile(p) and _formats.is_recording_file(p))
                           or (os.path.islink(p) and not os.path.exists(p)
                               and os.path.splitext(p)[1].lower() in _formats.input_extensions()))
            subs = sorted(n for n in os.listdir(item) if not n.startswith(".") and os.path.isdir(os.path.join(item, n))
                          and not (out and os.path.realpath(os.path.join(item, n)) == os.path.realpath(out))
                          and not (frames is not None and n.lower() == os.path.basename(frames).lower()))
            if frames is not None:      # an EasyMocap output folder: its keypoints2d/, smpl/, ... hold no takes
                subs = [n for n in subs if _holds_recordings(os.path.join(item, n))]
            if subs:
                named = ", ".join(subs[:5]) + (", ..." if len(subs) > 5 else "")
                print(f"blender_manikin: {item}: {len(subs)} sub-folder(s) not searched ({named}): "
                      "give them as inputs too, or use convert, which searches sub-folders", file=sys.stderr)
            if not found and frames is None:    # said, so a folder given by mistake is not passed over unseen
                print(f"blender_manikin: {item}: no recordings in this folder", file=sys.stderr)
            files.extend(found)
        else:
            files.append(item)
    first = {}
    for p in files:
        first.setdefault(os.path.realpath(p), p)
    return list(first.values())


def inapplicable_options(args, inputs):
    """Lines saying which given options do not apply to which of ``inputs`` (paths): ``--ik`` only
    to keypoint inputs, ``--model`` only to tracker recordings.  Printed once per run, so a batch
    that mixes both kinds is told how many inputs solve without the option.  An input that is not
    there (its own error says so) is counted as neither."""
    from .core.io_keypoints import is_keypoint_input
    kp = sum(bool(is_keypoint_input(p)) for p in inputs)
    trackers = sum(os.path.exists(p) for p in inputs) - kp
    notes = []
    if getattr(args, "ik", None) is not None and trackers:
        notes.append(f"--ik {args.ik}: not used for the {trackers} tracker recording(s) of {len(inputs)} "
                     f"input(s) (the pose network solves them; --ik chooses the IK of keypoint inputs)")
    model = str(getattr(args, "model", None) or "auto")
    if model.strip().lower() != "auto" and kp:
        notes.append(f"--model {model}: not used for the {kp} keypoint input(s) of {len(inputs)} "
                     f"input(s) (HybrIK IK solves them, without a pose network; --model is for tracker recordings)")
    return notes


def solve_settings(args):
    """The :class:`core.solve.SolveSettings` of the command-line options."""
    from .core import device_offsets
    from .core.solve import SolveSettings
    offsets = args.offsets
    if offsets and offsets.lower().endswith(".json"):
        offsets = device_offsets.load_offsets(offsets)
    layout, keypoint_layout = getattr(args, "layout", None), None
    if layout is not None and layout.strip().lower() in _keypoint_layouts():
        layout, keypoint_layout = None, layout.strip().lower()
    st = SolveSettings(axes=args.axes, units=args.units, fps=float(args.fps), offsets=offsets,
                       layout=layout, rate=getattr(args, "rate", None), keypoint_layout=keypoint_layout,
                       up=getattr(args, "up", None), smoothing=getattr(args, "smoothing", "auto"),
                       ik=getattr(args, "ik", None) or "adaptive", mapping=getattr(args, "mapping", None),
                       model=getattr(args, "model", None), sole=getattr(args, "sole", None),
                       floor=getattr(args, "floor", 0.0), fix_sides=not getattr(args, "keep_sides", False),
                       despike=not getattr(args, "keep_spikes", False),
                       keypoint_floor=getattr(args, "keypoint_floor", "feet"),
                       subject_params=getattr(args, "subject_params", None),
                       person=getattr(args, "person", "all"),
                       person_axis=getattr(args, "person_axis", None),
                       overlap=getattr(args, "overlap", SolveSettings.overlap),
                       teleports=getattr(args, "teleports", SolveSettings.teleports),
                       start=getattr(args, "start", None), end=getattr(args, "end", None),
                       posture=getattr(args, "posture", "standing"),
                       calibration_take=getattr(args, "calibration_take", None))
    if args.calibration_time is not None:
        st.calibration, st.tpose_time = "TPOSE", float(args.calibration_time)
        st.height, st.arm_span = args.height, args.arm_span
    elif args.height is not None and st.calibration_take:      # the take's pose, the typed height
        st.calibration, st.height, st.arm_span = "AUTO", float(args.height), args.arm_span
    elif args.height is not None:
        st.calibration, st.height, st.arm_span = "MEASURE", float(args.height), args.arm_span
    else:
        st.calibration = "AUTO"
    return st


def _config(path, args):
    from .blender.solve_job import SolveConfig
    from .core.solve import SolveSettings
    st = solve_settings(args)
    return SolveConfig(source="FILE", filepath=path, frame_start=1, create_trackers=bool(args.trackers),
                       live_rig=bool(args.live_rig), set_scene_range=True, armature_name="MANIKIN_body",
                       mark_problems=bool(getattr(args, "marks", True)),
                       body_mesh=bool(getattr(args, "mannequin", True)),
                       **{k: getattr(st, k) for k in SolveSettings.__dataclass_fields__})


def reset_scene(fps):
    """Empty factory scene at ``fps`` (integer ``render.fps`` and ``fps_base``).

    Only the scene is reset, never the preferences: ``read_factory_settings`` would also reset
    them, which disables every extension, this one included, and makes Blender remove the
    extensions' wheels (onnxruntime) from disk in the middle of a batch run."""
    import bpy
    bpy.ops.wm.read_homefile(use_factory_startup=True, use_empty=True)
    scene = bpy.context.scene
    n = max(1, int(round(fps)))
    scene.render.fps = n
    scene.render.fps_base = n / float(fps)
    return scene


def export_glb(path, output):
    """glTF binary of the armature (with its meshes, and the tracker empties), animation baked
    (:mod:`.blender.gltf_export`)."""
    from .blender import gltf_export
    gltf_export.export_glb(path, output.armature, extra_objects=list(output.trackers.values()))


def export_fbx(path, output, preset="blender"):
    """FBX of the armature (with its meshes, and the tracker empties), animation baked, with the
    FBX preset ``preset`` (:mod:`.blender.fbx_presets`)."""
    from .blender import fbx_presets
    fbx_presets.export_fbx(path, output.armature, preset, extra_objects=list(output.trackers.values()))


def convert_one_core(path, out_dir, args, formats, stem=None, keypoints=None):
    """Solve one recording with the numpy core and write JSON / BVH (no Blender needed);
    returns ``(written paths, outcome)``.  ``keypoints``: the
    :class:`.core.io_keypoints.KeypointRecording` of ``path`` already read (one person of a
    group file), solved instead of reading ``path`` again."""
    from .core.solve import solve_recording
    out = solve_recording(path if keypoints is None else keypoints, solve_settings(args))
    return write_core_formats(path, out_dir, out.result, args, formats, stem), out


def _stem(path):
    """The output name of the input ``path`` (``.`` and ``dir/`` name the folder), one Windows
    accepts (:func:`.core.file_names.windows_safe`: ``con.bsor`` -> ``con_``)."""
    from .core.file_names import windows_safe
    return windows_safe(os.path.splitext(os.path.basename(os.path.abspath(path)))[0])


def output_tail(formats) -> int:
    """The most characters written after a stem in ``--out`` for ``formats``: the longest
    extension, and the longer of a writer's own ``.tmp.npz`` and the FBX / glTF exporters'
    temporary folder ``.manikin-fbx-XXXXXXXX/`` or ``.manikin-glb-XXXXXXXX/`` (:func:`_write_whole`)."""
    ext = max((len(_formats.WRITERS[f].extension) for f in formats if f in _formats.WRITERS), default=0)
    return ext + max(len(".tmp.npz"), len(".manikin-fbx-XXXXXXXX") + 1)


def write_core_formats(path, out_dir, result, args, formats, stem=None):
    """Write ``result`` in each of ``formats`` the numpy core writes; returns the paths."""
    stem = stem or _stem(path)
    written = []
    for fmt in formats:
        writer = _formats.WRITERS[fmt]
        if writer.needs_blender:
            continue
        dst = os.path.join(out_dir, f"{stem}{writer.extension}")
        writer.write(dst, result, source=os.path.basename(path), options=args)
        written.append(dst)
    return written


def convert_one(path, out_dir, args, formats, stem=None, keypoints=None):
    """Solve one recording and write its outputs in Blender; returns ``(written paths, job)``.
    ``keypoints``: as :func:`convert_one_core`."""
    import dataclasses

    import bpy
    from .blender.solve_job import SolveJob

    reset_scene(args.fps)
    job = SolveJob(dataclasses.replace(_config(path, args), keypoints=keypoints))
    job.run(bpy.context)
    export = job.output
    if getattr(args, "retarget", None):
        from types import SimpleNamespace
        from .blender import retarget_apply
        char = append_character(args.retarget)
        bone_map, map_path = args.bone_map, None
        if bone_map.lower().endswith(".json"):
            bone_map, map_path = "file", args.bone_map
        _, _, notes = retarget_apply.retarget_onto(job.output.armature, char, bone_map, map_path,
                                                   args.root_motion, args.keep_ends,
                                                   live_swivel=getattr(args, "live_swivel", None))
        job.info.extend(f"retarget: {n}" for n in notes)
        export = SimpleNamespace(armature=char, trackers={})          # the character is what is exported
    stem = stem or _stem(path)
    preset = getattr(args, "fbx_preset", "blender")
    blender_writers = {"fbx": lambda dst: _write_whole(dst, lambda tmp: export_fbx(tmp, export, preset), "fbx"),
                       "glb": lambda dst: _write_whole(dst, lambda tmp: export_glb(tmp, export), "glb"),
                       "blend": _save_blend}
    written = []
    for fmt in formats:
        writer = _formats.WRITERS[fmt]
        dst = os.path.join(out_dir, f"{stem}{writer.extension}")
        if writer.needs_blender:
            # an absolute path: a Blender binary resolves a relative one against $PWD, which a
            # pipeline's subprocess(cwd=...) leaves pointing at its own folder, not this one
            blender_writers[fmt](os.path.abspath(dst))
            written.append(dst)
        else:
            written += write_core_formats(path, out_dir, job.result, args, [fmt], stem)
    return written, job


def _write_whole(dst, write, kind):
    """``write(path)`` (:func:`export_fbx`, :func:`export_glb`) to ``dst`` through a temporary
    folder ``.manikin-<kind>-XXXXXXXX`` beside it, renamed when complete (the exporters write as
    they go: an error or Ctrl-C would leave a truncated file at ``dst``)."""
    tmp_dir = tempfile.mkdtemp(prefix=f".manikin-{kind}-", dir=os.path.dirname(dst))
    try:
        tmp = os.path.join(tmp_dir, os.path.basename(dst))
        write(tmp)
        os.replace(tmp, dst)
    finally:
        shutil.rmtree(tmp_dir, ignore_errors=True)


def _save_blend(dst):
    """Save the solve's scene as the ``.blend`` ``dst`` (compressed), without the ``.blend1``
    backup Blender's *Save Versions* preference leaves beside a file saved over (a second run
    into the same folder left one per take)."""
    import bpy
    paths = bpy.context.preferences.filepaths
    keep = paths.save_version
    paths.save_version = 0
    try:
        bpy.ops.wm.save_as_mainfile(filepath=dst, copy=True, compress=True)
    finally:
        paths.save_version = keep


@contextlib.contextmanager
def _ctrl_c():
    """Ctrl-C (SIGINT) or SIGTERM (``kill``, a job scheduler's stop) stops the batch: yields a
    list that holds the signal once one came; the file being written is not left half-written.
    Blender's operators turn the ``KeyboardInterrupt`` into a ``RuntimeError`` (which would only
    fail the file being written), and a Blender binary's own handler ignores the first Ctrl-C."""
    got = []

    def handler(signum, frame):
        got.append(signum)
        raise KeyboardInterrupt

    olds = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            olds[sig] = signal.signal(sig, handler)
    except ValueError:            # not the main thread: leave the handlers as they are
        pass
    try:
        yield got
    finally:
        for sig, old in olds.items():
            if old is not None:   # None: a handler not set from Python (Blender's own)
                signal.signal(sig, old)


@contextlib.contextmanager
def quiet_stdout(to_stderr=False):
    """Keep stdout for the result lines only: inside this block anything printed to stdout,
    at Python or C level (Blender's "Info: Saved ...", the FBX exporter's progress, warnings
    Blender prints while ``import bpy`` starts it), is discarded, or sent to stderr with
    ``to_stderr=True`` (for warnings a user may need)."""
    sys.stdout.flush()
    saved = None
    try:
        fd = sys.__stdout__.fileno() if sys.__stdout__ is not None else None
    except (AttributeError, ValueError, OSError):
        fd = None
    if fd is not None:
        try:
            saved = os.dup(fd)
            if to_stderr:
                sys.stderr.flush()
                os.dup2(sys.__stderr__.fileno(), fd)
            else:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, fd)
                os.close(devnull)
        except (AttributeError, ValueError, OSError):
            saved = None
    try:
        with contextlib.ExitStack() as stack:
            sink = sys.stderr if to_stderr else stack.enter_context(open(os.devnull, "w"))
            stack.enter_context(contextlib.redirect_stdout(sink))
            yield
    finally:
        if saved is not None:
            try:
                sys.__stdout__.flush()
            except (AttributeError, ValueError, OSError):
                pass
            os.dup2(saved, fd)
            os.close(saved)


def _hint_dash_files(argv):
    """After a usage error: name the arguments that are files whose names start with ``-``
    (``-take.csv``), which argparse reads as options."""
    if "--" in argv:
        return
    dashed = [a for a in argv if a.startswith("-") and a != "-" and os.path.exists(a)]
    for a in dashed:
        print(f"blender_manikin: {a!r} is a file, read as an option: put -- before it "
              f"(solve --out DIR -- {a}) or write it as {os.path.join('.', a)}", file=sys.stderr)


def main(argv=None):
    """Command-line entry; returns the exit status."""
    parser = build_parser()
    if argv is None:
        argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:         # argparse: usage error (2) or --help (0)
        _hint_dash_files(argv)
        return int(exc.code or 0)
    try:
        formats = parse_formats(args.format)
    except ValueError as exc:
        print(f"blender_manikin: error: {exc}", file=sys.stderr)
        return 2
    if not (0 < args.fps < float("inf")):
        print("blender_manikin: error: --fps must be a positive number", file=sys.stderr)
        return 2
    if os.path.exists(args.out) and not os.path.isdir(args.out):
        print(f"blender_manikin: error: --out {args.out} is a file, not a folder", file=sys.stderr)
        return 2
    if args.command == "convert":
        return convert_main(args, formats)
    needs_blender = any(f in BLENDER_FORMATS for f in formats) or args.trackers or bool(args.retarget)
    if needs_blender:
        try:
            with quiet_stdout(to_stderr=True):   # Blender may print warnings as it starts
                import bpy  # noqa: F401  (availability check)
        except ImportError:
            what = [f for f in formats if f in BLENDER_FORMATS] + (["--trackers"] if args.trackers else []) + \
                (["--retarget"] if args.retarget else [])
            print(f"blender_manikin: error: {', '.join(what)} "
                  "needs Blender: run with Blender (blender -b --python cli.py -- ...) or install bpy "
                  "(json and bvh are written without it)", file=sys.stderr)
            return 2
    from .core.io_keypoints import is_keypoint_input
    from .core.recording import missing_file
    from .core.solve import error_message
    convert = convert_one if needs_blender else convert_one_core
    from .core import output_guard
    from .core.convert import folder_stems
    from .core.file_names import check_folder
    try:
        check_folder(args.out, output_tail(formats))      # too deep for Windows' 260 characters
    except ValueError as exc:
        print(f"blender_manikin: error: {exc}", file=sys.stderr)
        return 2
    if not args.dry_run:
        os.makedirs(args.out, exist_ok=True)
    inputs = expand_inputs(args.inputs, args.out)
    if not inputs:
        print("blender_manikin: error: no recordings found in the inputs", file=sys.stderr)
        return 1
    # (input, person or None, their recording or None): a keypoint file with several people, read
    # once, one job each (stems <stem>_p<label>)
    jobs = []
    for path in inputs:
        people = keypoint_people(path, args)
        if people and len(people) > 1:
            jobs.extend((path, lab, rec) for lab, rec in people)
        else:                   # one person: the file's own name (its recording, when read, solved)
            jobs.append((path, None, people[0][1] if people else None))
    # names that do not depend on the batch: an input written here before keeps its outputs' names
    # (the folder's record says which input each came from), a new one never takes another's;
    # two inputs named alike never write the same file; names Windows accepts, paths under 260
    names = folder_stems(inputs, {p: [lab for q, lab, _ in jobs if q == p] for p, lab, _ in jobs if lab is not None},
                         args.out, output_tail(formats))
    jobs = [(p, names[(p, None if lab is None else str(lab))], lab, rec) for p, lab, rec in jobs]
    notes = inapplicable_options(args, inputs)
    if args.dry_run:
        code = dry_run(jobs, args.out, formats, getattr(args, "overwrite", False))
        for note in notes:              # at the end, as a solve says them
            print(f"blender_manikin: {note}", file=sys.stderr, flush=True)
        return code
    failed = done = 0
    path = inputs[0]
    with _ctrl_c() as interrupted:
        try:
            for path, stem, person, keypoints in jobs:
                try:
                    if not os.path.isfile(path) and not is_keypoint_input(path):
                        raise FileNotFoundError(missing_file(path))
                    # nothing the user made or changed is replaced (core/output_guard.py)
                    dsts = [os.path.join(args.out, stem + _formats.WRITERS[f].extension) for f in formats]
                    output_guard.check_free(dsts, getattr(args, "overwrite", False))
                    output_guard.claim(dsts, path, person)
                    run_args = args if person is None else argparse.Namespace(**{**vars(args), "person": person})
                    with quiet_stdout():
                        written, job = convert(path, args.out, run_args, formats, stem, keypoints)
                    output_guard.record(written, path, person)
                except Exception as exc:      # one bad input does not stop the others
                    if interrupted:           # Ctrl-C, turned into an error by a Blender operator
                        raise KeyboardInterrupt from exc
                    failed += 1
                    done += 1
                    who = "" if person is None else f" [person {person}]"
                    print(f"ERROR {path}{who}: {error_message(exc)}", file=sys.stderr, flush=True)
                    continue
                done += 1
                who = "" if person is None else f" [person {person} of {_people_said(path, jobs)}]"
                print(f"OK {path}{who} -> {', '.join(written)} ({job.summary()})", flush=True)
                save_layout_once(args, job.recording)
        except KeyboardInterrupt:
            print(f"blender_manikin: interrupted during {path}: {done - failed} input(s) converted, "
                  f"{len(inputs) - done} not", file=sys.stderr, flush=True)
            return 128 + (interrupted[0] if interrupted else signal.SIGINT)   # 130 Ctrl-C, 143 SIGTERM
    for note in notes:                  # once per run, beside the batch's count
        print(f"blender_manikin: {note}", file=sys.stderr, flush=True)
    print(f"blender_manikin: {done - failed} converted, {failed} error(s) of {len(jobs)} input(s); "
          f"outputs in {args.out}", file=sys.stderr, flush=True)
    return 1 if failed else 0


def dry_run(jobs, out_dir, formats, overwrite=False):
    """``--dry-run``: print ``INPUT -> OUTPUTS`` for each of ``jobs`` (``(input, stem, person or
    None, recording)``), writing nothing; an input whose outputs the output guard would refuse
    (:func:`.core.output_guard.check_free`) or that is missing is an ``ERROR`` line on stderr.
    Returns the exit status: 0, or 1 when any input would fail so."""
    from .core import output_guard
    from .core.io_keypoints import is_keypoint_input
    from .core.recording import missing_file
    failed = 0
    for path, stem, person, _ in jobs:
        who = "" if person is None else f" [person {person}]"
        dsts = [os.path.join(out_dir, stem + _formats.WRITERS[f].extension) for f in formats]
        try:
            if not os.path.isfile(path) and not is_keypoint_input(path):
                raise FileNotFoundError(missing_file(path))
            output_guard.check_free(dsts, overwrite)
        except (OSError, ValueError) as exc:
            failed += 1
            print(f"ERROR {path}{who}: {exc}", file=sys.stderr, flush=True)
            continue
        print(f"{path}{who} -> {', '.join(dsts)}", flush=True)
    print(f"blender_manikin: dry run: {len(jobs) - failed} input(s) would be converted, {failed} error(s); "
          f"nothing written", file=sys.stderr, flush=True)
    return 1 if failed else 0


def keypoint_people(path, args):
    """``[(label, KeypointRecording), ...]``: the people a keypoint file at ``path`` holds with
    ``--person all`` (the default), read once (:func:`.core.io_keypoints.read_keypoint_people`;
    each is solved from its recording, not read again), or None: not a keypoint file, one
    chosen with ``--person``, a file that surely holds one person
    (:func:`.core.io_keypoints.one_person_file`, told from its header: its solve reads it when its
    turn comes, so a batch never holds every file's recording at once), or a file that cannot be
    read (its solve then says why)."""
    from .core.io_keypoints import is_keypoint_input, one_person_file, read_keypoint_people
    from .core.recording import RecordingError
    if str(getattr(args, "person", "all") or "all").strip().lower() != "all":
        return None
    try:
        if not is_keypoint_input(path) or one_person_file(path):
            return None
        layout = str(getattr(args, "layout", None) or "").strip().lower()
        people = read_keypoint_people(path, layout=layout if layout in _keypoint_layouts() else None,
                                      rate=getattr(args, "rate", None), mapping=getattr(args, "mapping", None),
                                      up=getattr(args, "up", None), units=getattr(args, "units", None),
                                      person_axis=getattr(args, "person_axis", None),
                                      subject_params=getattr(args, "subject_params", None))
    except (RecordingError, OSError, ValueError):
        return None
    return people


def _people_said(path, jobs):
    """``"3: 0, 1, 2"``: how many people of ``path`` are solved, and their labels."""
    labels = [p for q, _, p, _ in jobs if q == path]
    return f"{len(labels)}: {', '.join(labels)}"


def save_layout_once(args, recording):
    """``--save-layout``: write the first wide-layout input's layout (once)."""
    layout = (getattr(recording, "metadata", None) or {}).get("layout")
    if args.save_layout and layout and not getattr(args, "_layout_saved", False):
        from .core.io_wide_csv import save_layout
        save_layout(args.save_layout, layout)
        args._layout_saved = True
        print(f"layout of {recording.source} written to {args.save_layout}", file=sys.stderr)


def convert_main(args, fmts):
    """``convert``: Dask, no Blender (see :mod:`blender_manikin.core.convert`)."""
    try:
        from .core import convert
        import distributed  # noqa: F401
    except ImportError:
        print("blender_manikin: error: convert needs Dask: pip install 'blender-manikin[dask]' "
              "(or dask[distributed])", file=sys.stderr)
        return 2
    try:
        inputs = convert.collect_inputs(args.inputs, exclude=[args.out])   # outputs are not inputs
        settings = solve_settings(args)
        if args.save_layout and not args.dry_run:      # a dry run writes nothing
            from .core.formats import load_recording
            for path in inputs:
                if path.lower().endswith(".csv"):
                    save_layout_once(args, load_recording(path, args.axes, args.units, settings.layout,
                                                          settings.rate))
                    break
    except (ValueError, OSError) as exc:
        print(f"blender_manikin: error: {exc}", file=sys.stderr)
        return 2
    if not inputs:
        print("blender_manikin: error: no recordings found in the inputs", file=sys.stderr)
        return 1
    def report(rec):                  # each input's OK line as it finishes, before the summary
        if rec["status"] == "ok":
            print(f"OK {convert.said(rec)} -> {', '.join(rec['outputs'])} ({rec['frames']} frames, "
                  f"{rec['seconds']:.2f} s)", flush=True)

    with _ctrl_c() as interrupted:    # SIGTERM (a job scheduler's stop) as Ctrl-C
        try:
            code, records = convert.run(inputs, args.out, fmts, settings, scheduler=args.scheduler,
                                        workers=args.workers, options=args, progress=args.progress,
                                        report=report, dry_run=args.dry_run)
            for rec in records if args.dry_run else ():
                if rec["status"] in ("planned", "skipped"):
                    note = " (converted before: skipped)" if rec["status"] == "skipped" else ""
                    print(f"{convert.said(rec)} -> {', '.join(rec['outputs'])}{note}", flush=True)
        except (ValueError, OSError) as exc:   # a format it cannot write, a scheduler that does not
            print(f"blender_manikin: error: {exc}", file=sys.stderr)   # answer, an --out it cannot write into
            return 2
        except KeyboardInterrupt:     # run() said how far it got; the manifest holds it
            return 128 + (interrupted[0] if interrupted else signal.SIGINT)   # 130 Ctrl-C, 143 SIGTERM
    for note in inapplicable_options(args, inputs):       # once per run
        print(f"blender_manikin: {note}", file=sys.stderr, flush=True)
    return code


def exit_process(code):
    """Leave with exit status ``code`` (stdout and stderr flushed): ``sys.exit``, or ``os._exit``
    where the process would crash on its way out after a glTF export (Blender 4.2's ``bpy``
    module: :func:`.blender.gltf_export.exit_crashes`; a batch that converted every file exited
    139)."""
    sys.stdout.flush()
    sys.stderr.flush()
    gltf = sys.modules.get(f"{__package__ or 'blender_manikin'}.blender.gltf_export")
    if gltf is not None and gltf.exit_crashes():
        os._exit(code)
    sys.exit(code)


def _script_main():
    """Entry when this file is run as a plain script (``blender -b --python cli.py -- ...``)."""
    here = os.path.dirname(os.path.abspath(__file__))
    parent = os.path.dirname(here)
    if parent not in sys.path:
        sys.path.insert(0, parent)
    import importlib
    pkg = os.path.basename(here)
    cli = importlib.import_module(f"{pkg}.cli")
    cli.exit_process(cli.main())


if __name__ == "__main__" and not __package__:
    _script_main()
