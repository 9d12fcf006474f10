"""Accuracy and speed of MANIKIN against its baselines, on the Bandai Namco held-out takes and on
the HDM05 validation set (another studio, other people and motions), side by side, in one run.

    python benchmarks/bench_pose.py [--datasets bandai,hdm05,PATH] [--model M.onnx]
        [--previous-model P.onnx] [--fk-model F.onnx] [--pelvis-model P4.onnx]
        [--six-model P6.onnx] [--trackers 3,4,6] [--capture 72[,2,0.5,1]] [--smoothing auto|S]
        [--max-clips N] [--repeats N] [--markdown]

Your own mocap (another studio's, your performers): ``--datasets PATH`` with a folder, file or
``.tar.xz`` of BVH or ASF/AMC takes (joint map, units and axes detected as training detects
them), or a sources ``.json`` stating them (``training/dataset.py`` ``load_sources``), e.g.
``--datasets ~/mocap/studio_b --body tpose --capture 72``: every clip is a test clip.

Ground truth: every clip is mapped onto the 22-joint body and solved by HybrIK into the cache
the training uses (``training/dataset.py``; HDM05 through ``core/asf_amc.py``), and posed by FK
on the clip's own skeleton.  Inputs: its head and wrist joint poses.  Bandai: the validation
split (whole takes the network never saw).  HDM05: every clip (it is never trained on).

Each set is solved twice (``--body calibrated,gt``): with the body a T-pose calibration gives
(the solver's own proportions, ``skeleton.make_body``, sized to the performer's stature and
arm span, as for a real user: the error then includes the skeletons' differences), and with
the true skeleton.  ``--body tpose`` sizes each performer by the add-on's own calibration
instead (:func:`tpose_calibration`: the skeleton stood in its rest T-pose, measured from the head's
height above the floor and the wrists' distance, as a recording that starts with a T-pose is).
``--body head`` sizes each clip as the add-on sizes a recording with no calibration pose (a game
replay): the stature from the clip's standing head height (:func:`.solve.body_from_head_height`),
proportional arms (the add-on then lengthens arms that cannot reach; the benchmark does not).

Methods: (a) the shipped model, network + analytic limbs (``core.pipeline.solve``); (p) the
previously shipped model, same pipeline (a model of another backbone given as ``--model`` or
``--previous-model``, a Dual Attention Poser, is named in its row: "(p) MANIKIN, Dual Attention
Poser (manikin_dap.onnx)"); (b) the network-only baseline: the same backbone trained
to predict all 22 rotations, posed by FK (AvatarPoser-style, ``core.baselines.network_only``);
(c) classic IK: body under the head, straight spine, two-bone arms with a fixed pole, straight
planted legs (``core.baselines.classic_ik``).

Columns (frame-weighted means over clips, ``core.metrics``): MPJPE, U-PE, L-PE, knee and ankle
position errors (cm), H-PE (hands, cm), Jitter (10^2 m/s^3; GT: the ground truth's own),
GP (ground penetration, cm), foot skating (cm/s: horizontal speed of a predicted ankle on the
frames the ground-truth foot is planted), frames/s (the whole method on all the set's frames
in one call, best of ``--repeats`` calls, default 3, this machine's CPU; measured, never
asserted).

``--capture HZ[,MM[,DEG[,MS]]]`` (e.g. ``--capture 72``): the trackers as a headset records them
instead of the clip's own frames: sampled at HZ with position noise (σ MM per coordinate,
default 2 mm), rotation noise (σ DEG per axis, default 0.5°) and timestamp jitter (σ MS, default
1 ms), then resampled onto the clip's 30 fps frames by the import's own resampler
(:func:`captured_targets`); the same samples for every method.  The default: no capture, the
ground truth's joint poses on the clip's frames.

``--smoothing auto|SECONDS`` (default ``auto``, as the solve): the tracker smoothing of
:mod:`blender_manikin.core.smoothing` on every method's input, after the capture, as
``solve_recording`` does after resampling (``0``: none).

``--per-class``: under each table, MPJPE and L-PE per motion class (read from the clip's
file name: HDM05 ``HDM_bd_squat1Reps_001_120.amc`` -> squat, Bandai ``dataset-1_walk_...`` ->
walk) for the shipped and the previous model, frame-weighted within each class.

Tracker sets (issue 14; ``--trackers 3,4,6``, default all three, ``''`` or ``none``: no table):
a second table per dataset and body compares the same pipeline (``core.pipeline.solve``) fed
by more trackers, each with its own model, in the same pass over the clips:

* 3 trackers (head, hands): the shipped model (``--model``; the row of method (a), not solved
  twice);
* 4 trackers (+ pelvis): ``--pelvis-model`` (default ``models/manikin_s_pelvis.onnx``);
* 6 trackers (+ pelvis, feet): ``--six-model`` (default ``models/manikin_s_six.onnx``).

A model's ONNX contract names the devices it takes (``contract.devices``); its inputs come from
the ground truth like the three trackers': each device's joint (``core.devices.DEVICE_JOINT``:
pelvis tracker = pelvis joint, foot trackers = ankle joints) position and world rotation.  The
pelvis tracker drives the root; the foot trackers are the legs' ankle targets.  With the
calibrated body, sets with a pelvis tracker also get the legs a T-pose calibration measures from
it (``calibrated_body(legs=True)``), as a real six-tracker solve does.  A row whose
model file is absent (or whose contract lists other devices) is skipped, with a message on
stderr.  Columns: MPJPE, L-PE, knee, ankle (cm), ankle->target (mean and max distance of the
solved ankle joints to the foot trackers' targets, mm, sets with feet only; with the true
skeleton it should be ~0, with the calibrated body a leg that cannot reach its tracker leaves a
gap), skate (cm/s), Jitter, Jitter-GT (10^2 m/s^3) and frames/s, as above.  Under each table:
the six-tracker MPJPE over the three-tracker MPJPE (issue 14's target on HDM05: <= 0.4).  An
anchor row quotes SparsePoser's own figures (Ponton et al. 2023, Table 1: six 6-DoF trackers,
trained on DanceDB, tested on AMASS HUMAN4D; Pos = mean joint position error with the root
aligned to the ground truth, and Jitter): quoted from the paper, not measured here, on other
data, so only a scale, not a comparison on equal terms.
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from blender_manikin.core import baselines, features, metrics, pipeline, rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402
from blender_manikin.core.devices import DEVICE_JOINT, REQUIRED_DEVICES  # noqa: E402
from blender_manikin.core.model_choice import BACKBONE_LABELS  # noqa: E402
from blender_manikin.core.model_runner import ModelRunner, MODELS_DIR  # noqa: E402
from blender_manikin.core.pose_result import TrackerTargets  # noqa: E402
from blender_manikin.core.smoothing import parse_smoothing, smooth_targets  # noqa: E402
from blender_manikin.core.solve import body_from_head_height  # noqa: E402

SHARED = os.path.join(os.path.dirname(ROOT), "shared", "data")
DATASETS = {
    "bandai": (os.path.join(SHARED, "bandai-namco-motion.tar.xz"), "val"),
    "hdm05": (os.path.join(SHARED, "validation", "hdm05-subset.tar.xz"), "all"),
}
DEFAULT_BVH = DATASETS["bandai"][0]
PREVIOUS = os.path.join(ROOT, "benchmarks", "models", "manikin_s_previous.onnx")
COLUMNS = ["MPJPE", "U-PE", "L-PE", "knee", "ankle", "H-PE", "Jitter", "Jitter-GT", "GP", "skate", "frames/s"]
UNITS = {"MPJPE": "cm", "U-PE": "cm", "L-PE": "cm", "knee": "cm", "ankle": "cm", "H-PE": "cm",
         "Jitter": "1e2 m/s^3", "Jitter-GT": "1e2 m/s^3", "GP": "cm", "skate": "cm/s", "frames/s": ""}
KNEES = [sk.J["left_knee"], sk.J["right_knee"]]
ANKLES = [sk.J["left_ankle"], sk.J["right_ankle"]]
FOOT_DEVICES = ("left_foot", "right_foot")       # in ANKLES order

# tracker-set table (issue 14): key -> (row name, the devices its model must take)
TRACKER_SETS = {
    "3": ("3 trackers (head, hands)", REQUIRED_DEVICES),
    "4": ("4 trackers (+ pelvis)", REQUIRED_DEVICES + ("pelvis",)),
    "6": ("6 trackers (+ pelvis, feet)", REQUIRED_DEVICES + ("pelvis", "left_foot", "right_foot")),
}
SHIPPED = "(a) MANIKIN, shipped model"
PREVIOUS_ROW = "(p) MANIKIN, previous model"


def row_label(key, runner):
    """The tables' name of the row ``key`` (:data:`SHIPPED` or :data:`PREVIOUS_ROW`) solved with
    ``runner``: ``key`` for the Transformer (posenet); for another backbone (the contract's
    ``architecture.arch``) its name and file in place of "shipped/previous model", as
    ``"(p) MANIKIN, Dual Attention Poser (manikin_dap.onnx)"``."""
    arch = getattr(runner.contract, "arch", None)
    if arch not in BACKBONE_LABELS:
        return key
    return f"{key.split(',')[0]}, {BACKBONE_LABELS[arch]} ({os.path.basename(runner.path)})"
#: ``--body`` modes and their table titles
BODY_TITLES = {"calibrated": "calibrated body (T-pose: stature and arm span)", "gt": "true skeleton",
               "tpose": "T-pose calibration (the add-on's, from the performer's T-pose)",
               "head": "no calibration pose (the add-on's fallback: stature from the standing head height)"}
BODY_MODES = tuple(BODY_TITLES)
TRACKER_COLUMNS = ["MPJPE", "L-PE", "knee", "ankle", "ankle→target", "ankle→target max", "skate",
                   "Jitter", "Jitter-GT", "frames/s"]
TRACKER_UNITS = {**UNITS, "ankle→target": "mm", "ankle→target max": "mm"}
MAX_KEYS = {"ankle→target max"}                 # aggregated over clips as a maximum, not a mean
# quoted from ../shared/papers/sparseposer.md (Ponton et al., ACM TOG 2023), Table 1, HUMAN4D
# column: "Pos (cm)" (all joints, root aligned to the ground truth) and "Jitter (10^2m/s^3)";
# Ours-0: no added latency, Ours-7: 7 future frames.  Not measured here; its own data.
SPARSEPOSER = [
    ("SparsePoser Ours-0 (paper, Tab. 1, HUMAN4D; its own data, 6 trackers; quoted, not measured)",
     {"MPJPE": 2.90, "Jitter": 3.30}),
    ("SparsePoser Ours-7 (paper, Tab. 1, HUMAN4D, 7 future frames; quoted, not measured)",
     {"MPJPE": 2.49, "Jitter": 2.83}),
]


def load_clip(path):
    """``(body, local (T,22,3,3), positions (T,22,3), world (T,22,3,3), fps)`` of a cache clip, posed
    by FK on its own skeleton."""
    body, local, pos, world, fps, _ = load_clip_with_contacts(path)
    return body, local, pos, world, fps


def load_clip_with_contacts(path):
    with np.load(path) as z:
        body = sk.Body.from_offsets(z["offsets"], z["root_rest"], stature=float(z["stature"]))
        local = rot.quat_to_matrix(z["local_quat"].astype(np.float64))
        root = z["root_pos"].astype(np.float64)
        fps = float(z["fps"])
        contacts = z["contacts"].astype(bool)
    pos, world = sk.forward_kinematics(local, root, body)
    return body, local, pos, world, fps, contacts


def targets_from_gt(pos, world, fps, devices=REQUIRED_DEVICES):
    """Tracker targets of ``devices`` (default head and hands) from the ground truth: each
    device's joint (``DEVICE_JOINT``: head, wrists, pelvis, ankles) position and world rotation."""
    dev = {d: DEVICE_JOINT[d] for d in devices}
    return TrackerTargets(fps=fps, pos={d: pos[:, j].copy() for d, j in dev.items()},
                          rot={d: world[:, j].copy() for d, j in dev.items()})


#: ``--capture`` fields, in order, with their defaults past the rate
CAPTURE_FIELDS = ("rate", "pos_mm", "rot_deg", "time_ms")
CAPTURE_DEFAULTS = (None, 2.0, 0.5, 1.0)


def parse_capture(text):
    """``--capture HZ[,MM[,DEG[,MS]]]`` -> ``{"rate", "pos_mm", "rot_deg", "time_ms"}``, or None
    for an empty text.  Raises SystemExit naming the field that is not a positive (or, past
    the rate, non-negative) number."""
    if not text:
        return None
    parts = [p.strip() for p in text.split(",")]
    if len(parts) > len(CAPTURE_FIELDS):
        raise SystemExit(f"--capture {text!r}: at most {len(CAPTURE_FIELDS)} values "
                         f"({','.join(CAPTURE_FIELDS)})")
    out = dict(zip(CAPTURE_FIELDS, CAPTURE_DEFAULTS))
    for name, p in zip(CAPTURE_FIELDS, parts):
        try:
            v = float(p)
        except ValueError:
            raise SystemExit(f"--capture {text!r}: {name} {p!r} is not a number") from None
        if not np.isfinite(v) or v < 0 or (name == "rate" and v <= 0):
            raise SystemExit(f"--capture {text!r}: {name} must be {'positive' if name == 'rate' else '>= 0'}, "
                             f"got {p}")
        out[name] = v
    return out


def captured_targets(targets, capture, seed):
    """``targets`` as a headset would record and the add-on import them: each device sampled at
    ``capture["rate"]`` Hz, at instants off their logged timestamps by Gaussian jitter
    (σ ``time_ms``, one draw per sample shared by all devices, as one runtime frame), with
    Gaussian position noise (σ ``pos_mm`` per coordinate) and rotation noise (a random
    rotation vector, σ ``rot_deg`` per axis, applied in world axes), then resampled onto the
    clip's frame grid by :func:`blender_manikin.core.resample.resample` (the import's own
    resampler: interpolation, jump and freeze checks; not its head-height check, which a clip
    lying on the floor would fail).

    targets: :class:`TrackerTargets` on the clip's frames (``fps``, ``(T, 3)`` metres,
    ``(T, 3, 3)``).  seed: ``int`` or sequence; a device's noise depends on the seed and the
    device only, so every tracker set sees the same samples of the devices it shares.
    Returns ``(TrackerTargets, T')``: the grid from 0 s to the last logged sample, ``T' <= T``
    frames (the ground truth's first ``T'`` frames are its match).
    """
    from blender_manikin.core.devices import DEVICES
    from blender_manikin.core.recording import Recording, TrackerStream
    from blender_manikin.core.resample import resample
    fps, T = float(targets.fps), targets.num_frames
    dur = (T - 1) / fps
    n = int(np.floor(dur * capture["rate"] + 1e-9)) + 1
    logged = np.arange(n) / capture["rate"]
    rng = np.random.default_rng(seed)
    actual = np.clip(logged + rng.normal(0.0, capture["time_ms"] / 1000.0, n), 0.0, dur)
    f = actual * fps
    i0 = np.minimum(np.floor(f).astype(int), T - 1)
    i1 = np.minimum(i0 + 1, T - 1)
    w = f - i0
    streams = {}
    for d in targets.pos:
        drng = np.random.default_rng([*np.atleast_1d(seed), 1 + DEVICES.index(d)])
        P = targets.pos[d]
        pos = (1 - w)[:, None] * P[i0] + w[:, None] * P[i1]
        pos = pos + drng.normal(0.0, capture["pos_mm"] / 1000.0, pos.shape)
        q = rot.quat_continuous(rot.matrix_to_quat(targets.rot[d]))
        q = rot.quat_slerp(q[i0], q[i1], w)
        noise = rot.axis_angle_to_quat(drng.normal(0.0, np.deg2rad(capture["rot_deg"]), (n, 3)))
        streams[d] = TrackerStream(d, logged, pos, rot.quat_mul(noise, q))
    times, pos, quat, valid, _ = resample(Recording(streams=streams, source="captured"), fps,
                                          t_start=0.0, t_end=float(logged[-1]), required=tuple(streams),
                                          check_units=False)      # metres by construction
    return (TrackerTargets(fps=fps, pos={d: pos[d] for d in streams},
                           rot={d: rot.quat_to_matrix(quat[d]) for d in streams},
                           valid={d: valid[d] for d in streams}), int(times.shape[0]))


def calibrated_body(gt_body, legs=False):
    """The body a T-pose calibration builds for this performer: the solver's proportions at the
    performer's stature (the skeleton's head joint above its ankles by the body model's proportions,
    :func:`~blender_manikin.core.skeleton.stature_from_head_above_ankles`, as the calibration
    sizes a body from the head's height) and wrist-to-wrist span.
    legs: with a pelvis tracker the T-pose also measures the legs from the pelvis joint's height
    (``calibration._legs_from_pelvis_height``: the skeleton's pelvis above its ankles, plus the
    model's ankle height, split into thigh and shank by the proportions)."""
    from blender_manikin.core.calibration import _legs_from_pelvis_height
    stature = float(sk.stature_from_head_above_ankles(features.head_above_ankles(gt_body.offsets)))
    rest = gt_body.rest_positions()
    span = float(np.linalg.norm(rest[sk.J["left_wrist"]] - rest[sk.J["right_wrist"]]))
    m = sk.BodyMeasurements(stature=stature, arm_span=span)
    if legs:
        ankle_z = 0.5 * (rest[sk.J["left_ankle"], 2] + rest[sk.J["right_ankle"], 2])
        pelvis_z = rest[sk.J["pelvis"], 2] - ankle_z + sk.PROPORTIONS["ankle_height"] * stature + sk.SOLE
        leg = _legs_from_pelvis_height(pelvis_z, stature)
        m = sk.BodyMeasurements(stature=stature, arm_span=span, thigh=leg["thigh"], shank=leg["shank"])
    return sk.make_body(m)


def tpose_calibration(gt_body, devices=REQUIRED_DEVICES):
    """What the add-on's own T-pose calibration makes of this performer (``--body tpose``): the
    performer's skeleton stood for 4 s in its rest pose, a T-pose, with a 1 cm sway
    (``benchmarks/standing.py``), its ``devices`` given their joints' poses, the T-pose found
    (:func:`.calibration.find_tpose`), measured (:func:`.calibration.calibrate`: stature from
    the head's height above the floor, arm span, with a pelvis tracker the legs, and the device
    offsets: the pelvis and foot trackers' measured whole) and sized
    (:func:`.calibration.body_for`), as a recording that starts with a T-pose is.  Unlike
    :func:`calibrated_body` it goes through the floor the clip's skeleton stands on, as a real
    calibration does.  Returns ``(Body, offsets)`` (offsets: the device-offsets dict to apply to
    the clip's device poses, :func:`with_offsets`).  Raises ValueError when no plausible T-pose
    is found."""
    from blender_manikin.core import calibration as cal
    from standing import standing_targets
    targets = standing_targets(gt_body, "T", devices=devices)
    cand = cal.find_tpose(targets)
    if not cand.plausible:
        raise ValueError(f"no plausible T-pose in the performer's rest pose: {cand}")
    res = cal.calibrate(targets, frame=cand.frame)
    return cal.body_for(res.measurements), res.offsets


def with_offsets(targets, offsets):
    """``targets`` (:class:`TrackerTargets`, device poses: here the joints' own) with the device
    ``offsets`` applied by :func:`.device_offsets.to_targets`, as the solve applies the calibrated
    offsets to a recording's devices."""
    from blender_manikin.core.device_offsets import to_targets
    T = targets.num_frames
    quat = {d: rot.matrix_to_quat(targets.rot[d]) for d in targets.rot}
    return to_targets(np.arange(T) / targets.fps, targets.pos, quat, targets.valid, offsets, fps=targets.fps)


def clip_metrics(res, gt_local, gt_pos, fps, contacts, targets=None):
    """The clip's metrics; with ``targets`` that have foot trackers, also the solved ankles'
    distance to them (``ankle→target``: mean, ``ankle→target max``: max, mm)."""
    ev = metrics.evaluate(res.positions, res.local_rot, gt_pos, gt_local, fps)
    P = res.positions
    ev["knee"] = float(100 * np.linalg.norm(P[:, KNEES] - gt_pos[:, KNEES], axis=-1).mean())
    ev["ankle"] = float(100 * np.linalg.norm(P[:, ANKLES] - gt_pos[:, ANKLES], axis=-1).mean())
    speed = np.zeros((P.shape[0], 2))
    if P.shape[0] > 1:
        speed[1:] = np.linalg.norm(np.diff(P[:, ANKLES, :2], axis=0), axis=-1) * fps
    planted = contacts[:, :2]
    ev["skate"] = float(100 * speed[planted].mean()) if planted.any() else 0.0
    if targets is not None and all(d in targets.pos for d in FOOT_DEVICES):
        goal = np.stack([targets.pos[d] for d in FOOT_DEVICES], 1)              # (T, 2, 3)
        gap = 1000 * np.linalg.norm(P[:, ANKLES] - goal, axis=-1)
        ev["ankle→target"], ev["ankle→target max"] = float(gap.mean()), float(gap.max())
    return ev


PER_CLASS_METHODS = (SHIPPED, PREVIOUS_ROW)
PER_CLASS_COLUMNS = ("MPJPE", "L-PE")


def motion_class(path):
    """The motion class in a cache clip's file name (``"squat"``, ``"walk"``; the training data's
    :func:`~blender_manikin.training.dataset.motion_class`), or ``"other"``."""
    from blender_manikin.training import dataset
    return dataset.motion_class(path) or "other"


def add_mocap_datasets(token):
    """Register the mocap of ``token`` (not one of :data:`DATASETS`) as datasets of its own, every
    clip a test clip, and return their names: a folder, file or ``.tar.xz`` of BVH or ASF/AMC
    takes (joint map, units and axes detected as training detects them), or a ``.json`` sources
    file (``training/dataset.py`` ``load_sources``: each source's joint map, units, axes, fps),
    one dataset per source.  Raises SystemExit naming what is wrong."""
    from blender_manikin.training import dataset
    if token.lower().endswith(".json"):
        try:
            sources = dataset.load_sources(token)
        except (OSError, ValueError) as exc:
            raise SystemExit(f"--datasets {token}: {exc}") from None
    elif os.path.exists(token):
        sources = [dataset.MotionSource(path=token)]
    else:
        raise SystemExit(f"unknown dataset {token!r}: choose from {', '.join(DATASETS)}, or give a folder, "
                         f"archive or file of BVH / ASF-AMC mocap, or a sources .json")
    names = []
    for src in sources:
        name = src.name or os.path.basename(os.path.normpath(src.path))
        DATASETS[name] = (src, "all")
        names.append(name)
    return names


def dataset_files(name, max_clips=0):
    from blender_manikin.training import dataset   # the training cache (numpy only here)
    source, part = DATASETS[name]
    path = getattr(source, "path", source)
    if not os.path.exists(path):
        return None, path
    files = dataset.build_cache(source, verbose=False)
    if part == "val":
        files = dataset.split_files(files)[1]
    return (files[:max_clips] if max_clips else files), path


def needs(devices, fn):
    """``fn`` (``fn(targets, body) -> PoseResult``) marked as taking the trackers ``devices``."""
    fn.devices = tuple(devices)
    return fn


def run_dataset(name, methods, args, body_mode):
    """Every method on every clip of ``name``, then each on all the clips at once (speed).

    methods: ``{name: fn(targets, body)}``; ``fn.devices`` (see :func:`needs`; default head
    and hands) names the trackers it takes: the targets of each device set are built once a clip.
    """
    files, source = dataset_files(name, args.max_clips)
    if files is None:
        print(f"{name}: {source} not found, skipped", file=sys.stderr)
        return None
    devs = {m: tuple(getattr(fn, "devices", REQUIRED_DEVICES)) for m, fn in methods.items()}
    sums = {m: {} for m in methods}
    by_class = {}           # class -> {"clips", "frames", (method, column): frame-weighted sum}
    frames, all_targets = 0, []
    tpose_cache = {}
    for i, f in enumerate(files):
        gt_body, gt_local, gt_pos, gt_world, fps, contacts = load_clip_with_contacts(f)
        T = gt_pos.shape[0]
        if T < 4:
            continue
        sets = set(devs.values())
        if body_mode == "calibrated":
            bodies = {d: calibrated_body(gt_body, legs="pelvis" in d) for d in sets}
        elif body_mode == "tpose":
            key = gt_body.offsets.tobytes() + gt_body.root_rest.tobytes()      # one per performer
            for d in sets:
                if (key, d) not in tpose_cache:
                    tpose_cache[key, d] = tpose_calibration(gt_body, d)
            bodies = {d: tpose_cache[key, d][0] for d in sets}
        elif body_mode == "gt":
            bodies = {d: gt_body for d in sets}
        tgs = {d: targets_from_gt(gt_pos, gt_world, fps, d) for d in sets}
        if args.capture:
            caught = {d: captured_targets(tg, args.capture, seed=[0, i]) for d, tg in tgs.items()}
            tgs = {d: c[0] for d, c in caught.items()}
            T = min(c[1] for c in caught.values())
            tgs = {d: TrackerTargets(fps=tg.fps, pos={k: v[:T] for k, v in tg.pos.items()},
                                     rot={k: v[:T] for k, v in tg.rot.items()},
                                     valid={k: v[:T] for k, v in tg.valid.items()}) for d, tg in tgs.items()}
            gt_local, gt_pos, contacts = gt_local[:T], gt_pos[:T], contacts[:T]
        if body_mode == "tpose":          # the calibrated device offsets, as the solve applies them
            tgs = {d: with_offsets(tg, tpose_cache[key, d][1]) for d, tg in tgs.items()}
        tgs = {d: smooth_targets(tg, args.smoothing)[0] for d, tg in tgs.items()}     # as the solve does
        if body_mode == "head":           # each clip a recording without a T-pose, sized by its head
            bodies = {d: body_from_head_height(tg) for d, tg in tgs.items()}
        frames += T
        all_targets.append((tgs, bodies))
        cls = by_class.setdefault(motion_class(f), {"clips": 0, "frames": 0})
        cls["clips"] += 1
        cls["frames"] += T
        for m, fn in methods.items():
            tg = tgs[devs[m]]
            ev = clip_metrics(fn(tg, bodies[devs[m]]), gt_local, gt_pos, fps, contacts, targets=tg)
            for k, v in ev.items():
                sums[m][k] = max(sums[m].get(k, v), v) if k in MAX_KEYS else sums[m].get(k, 0.0) + v * T
            if m in PER_CLASS_METHODS:
                for k in PER_CLASS_COLUMNS:
                    cls[m, k] = cls.get((m, k), 0.0) + ev[k] * T
        if not args.markdown:
            print(f"\r{name}: {i + 1}/{len(files)} clips, {frames} frames", end="", file=sys.stderr)
    if not args.markdown:
        print(file=sys.stderr)
    # speed: every clip back to back as one sequence, solved in one call
    bigs = {}
    for d in set(devs.values()):
        tgs = [t[d] for t, _ in all_targets]
        bigs[d] = TrackerTargets(fps=tgs[0].fps, pos={k: np.concatenate([t.pos[k] for t in tgs]) for k in d},
                                 rot={k: np.concatenate([t.rot[k] for t in tgs]) for k in d})
    rows = []
    for m, fn in methods.items():
        big = bigs[devs[m]]
        body0 = all_targets[0][1][devs[m]]
        fn(TrackerTargets(fps=big.fps, pos={d: v[:200] for d, v in big.pos.items()},
                          rot={d: v[:200] for d, v in big.rot.items()}), body0)     # warm-up
        best = float("inf")
        for _ in range(max(1, args.repeats)):        # the best of a few: the least disturbed run
            t = time.perf_counter()
            fn(big, body0)
            best = min(best, time.perf_counter() - t)
        row = {k: (v if k in MAX_KEYS else v / frames) for k, v in sums[m].items()}
        row["frames/s"] = big.num_frames / max(best, 1e-9)
        rows.append((m, row))
    return dict(name=name, body=body_mode, source=source, clips=len(files), frames=frames, rows=rows,
                by_class=by_class)


def print_class_table(r):
    """MPJPE and L-PE per motion class of result ``r`` (:func:`run_dataset`), for the shipped and
    the previous model, classes sorted by the shipped model's MPJPE, worst first."""
    cls = r["by_class"]
    methods = [m for m in PER_CLASS_METHODS if any((m, "MPJPE") in c for c in cls.values())]
    short = {SHIPPED: "(a)", PREVIOUS_ROW: "(p)"}
    cols = ["clips", "frames"] + [f"{short[m]} {k} [cm]" for m in methods for k in PER_CLASS_COLUMNS]
    rows = []
    for name, c in cls.items():
        row = {"clips": c["clips"], "frames": c["frames"]}
        for m in methods:
            for k in PER_CLASS_COLUMNS:
                row[f"{short[m]} {k} [cm]"] = c[m, k] / max(c["frames"], 1)
        rows.append((name, row))
    if methods:
        rows.sort(key=lambda nr: -nr[1][f"{short[methods[0]]} MPJPE [cm]"])
    print(f"\nper motion class, {r['name']}, {r['body']} body:")
    print(metrics.format_table(rows, cols, name_header="class"))


def tracker_set_methods(args):
    """``({set key: (row label, method name)}, {method name: fn})`` for ``--trackers``: the
    three-tracker set is method (a) itself; a set whose model is absent, or takes other
    devices, is skipped with a message on stderr."""
    keys = [k.strip() for k in (args.trackers or "").split(",") if k.strip()]
    if keys == ["none"]:
        keys = []
    for k in keys:
        if k not in TRACKER_SETS:
            raise SystemExit(f"unknown tracker set {k!r}: choose from {', '.join(TRACKER_SETS)} (or none)")
    paths = {"4": args.pelvis_model, "6": args.six_model}
    names, methods = {}, {}
    for k in TRACKER_SETS:
        if k not in keys:
            continue
        label, want = TRACKER_SETS[k]
        if k == "3":
            names[k] = (f"{label} ({os.path.basename(args.model)})", SHIPPED)
            continue
        if not os.path.isfile(paths[k]):
            print(f"tracker sets: {label}: no model at {paths[k]}, row skipped", file=sys.stderr)
            continue
        runner = ModelRunner(paths[k])
        if set(runner.contract.devices) != set(want):
            print(f"tracker sets: {label}: {paths[k]} takes {', '.join(runner.contract.devices)}, "
                  f"not {', '.join(want)}; row skipped", file=sys.stderr)
            continue
        names[k] = (f"{label} ({os.path.basename(paths[k])})", f"{label}: {paths[k]}")
        methods[names[k][1]] = needs(runner.contract.devices,
                                     lambda tg, b, runner=runner: pipeline.solve(tg, b, runner,
                                                                                 overlap=args.overlap))
    return names, methods


def print_tracker_table(r, names, what):
    """The tracker-set table of result ``r`` (rows of :func:`run_dataset`; ``names`` from
    :func:`tracker_set_methods`), its ratio line and the SparsePoser anchor."""
    rows = dict(r["rows"])
    label = lambda k: f"{k} [{TRACKER_UNITS[k]}]" if TRACKER_UNITS.get(k) else k      # noqa: E731
    table = [(row_label, {label(c): rows[m].get(c) for c in TRACKER_COLUMNS}) for row_label, m in names.values()]
    table += [(name, {label(c): v for c, v in row.items()}) for name, row in SPARSEPOSER]
    fmt = {label(k): v for k, v in {"frames/s": ",.0f", "MPJPE": ".2f", "ankle→target": ".3f",
                                    "ankle→target max": ".3f"}.items()}
    print(f"\ntracker sets, {r['name']}, {what}:")
    print(metrics.format_table(table, [label(c) for c in TRACKER_COLUMNS], name_header="trackers", formats=fmt))
    if "3" in names and "6" in names:
        ratio = rows[names["6"][1]]["MPJPE"] / rows[names["3"][1]]["MPJPE"]
        print(f"\nsix-tracker MPJPE / three-tracker MPJPE: {ratio:.3f} "
              f"(issue 14's target on HDM05: <= 0.4)")
    print("\nSparsePoser rows: quoted from the paper, not measured here (Ponton et al. 2023, Table 1, AMASS "
          "HUMAN4D, their network trained on DanceDB; MPJPE = their 'Pos', all joints, root aligned to the ground "
          "truth; Jitter: mean jerk at their data's frame rate; on SOMA: Pos 2.72 (Ours-0) / 2.22 (Ours-7) cm)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--datasets", default="bandai,hdm05",
                    help="comma-separated: " + ",".join(DATASETS) + ", or your own mocap: a folder, file or .tar.xz "
                         "of BVH or ASF/AMC takes, or a sources .json (every clip a test clip)")
    ap.add_argument("--model", default=os.path.join(MODELS_DIR, "manikin_s.onnx"))
    ap.add_argument("--previous-model", default=PREVIOUS, help="the model shipped before (skipped if absent)")
    ap.add_argument("--fk-model", default=os.path.join(ROOT, "benchmarks", "models", "baseline_fk.onnx"),
                    help="the network-only baseline (kind fk; not shipped in the add-on)")
    ap.add_argument("--pelvis-model", default=os.path.join(MODELS_DIR, "manikin_s_pelvis.onnx"),
                    help="the four-tracker model (head, hands, pelvis; row skipped if absent)")
    ap.add_argument("--six-model", default=os.path.join(MODELS_DIR, "manikin_s_six.onnx"),
                    help="the six-tracker model (head, hands, pelvis, feet; row skipped if absent)")
    ap.add_argument("--trackers", default="3,4,6",
                    help="tracker sets compared in the second table, comma-separated from 3,4,6 "
                         "('' or none: no table)")
    ap.add_argument("--body", default="calibrated,gt",
                    help="bodies to solve with, comma-separated: calibrated (the body model at the "
                         "skeleton's stature and arm span), gt (the true skeleton) and/or tpose (what the "
                         "add-on's calibration builds from the performer standing in a T-pose) and/or "
                         "head (no calibration pose: each clip sized by its standing head height, "
                         "proportional arms, as a game replay is)")
    ap.add_argument("--max-clips", type=int, default=0, help="limit the clips per dataset (0: all)")
    ap.add_argument("--repeats", type=int, default=3,
                    help="timed solves of the whole set per method; frames/s is the best (default 3)")
    ap.add_argument("--capture", type=parse_capture, default=None, metavar="HZ[,MM[,DEG[,MS]]]",
                    help="trackers as a headset records them: sampled at HZ with position noise MM "
                         "(σ per coordinate, default 2), rotation noise DEG (default 0.5) and timestamp "
                         "jitter MS (default 1), resampled by the import's resampler, e.g. --capture 72")
    ap.add_argument("--smoothing", type=parse_smoothing, default="auto", metavar="auto|SECONDS",
                    help="the tracker smoothing every method's input gets, as the solve's --smoothing "
                         "(default auto)")
    ap.add_argument("--overlap", type=int, choices=pipeline.OVERLAP_CHOICES, default=pipeline.DEFAULT_OVERLAP,
                    help="network windows seeing each frame, for every MANIKIN row (the solve's --overlap; "
                         "default 2)")
    ap.add_argument("--markdown", action="store_true", help="print only the tables")
    ap.add_argument("--per-class", action="store_true",
                    help="also MPJPE and L-PE per motion class (shipped and previous model)")
    args = ap.parse_args(argv)
    names = []
    for token in [d.strip() for d in args.datasets.split(",") if d.strip()]:
        names += [token] if token in DATASETS else add_mocap_datasets(token)
    for name in names:          # caches built (in worker processes) before any ONNX session's threads
        dataset_files(name, args.max_clips)

    runner = ModelRunner(args.model)
    methods = {SHIPPED: lambda tg, b: pipeline.solve(tg, b, runner, overlap=args.overlap)}
    labels = {SHIPPED: row_label(SHIPPED, runner)}          # a DAP model's rows name its backbone
    if os.path.isfile(args.previous_model) and os.path.abspath(args.previous_model) != os.path.abspath(args.model):
        prev = ModelRunner(args.previous_model)
        methods[PREVIOUS_ROW] = lambda tg, b: pipeline.solve(tg, b, prev, overlap=args.overlap)
        labels[PREVIOUS_ROW] = row_label(PREVIOUS_ROW, prev)
    if os.path.isfile(args.fk_model):
        fk_runner = ModelRunner(args.fk_model)
        methods["(b) network only (FK, AvatarPoser-style)"] = lambda tg, b: baselines.network_only(tg, b, fk_runner)
    methods["(c) classic IK (Blender-style rig)"] = lambda tg, b: baselines.classic_ik(tg, b)
    main_methods = list(methods)
    set_names, set_methods = tracker_set_methods(args)
    methods.update(set_methods)

    results = []
    for name in names:
        for body_mode in [b.strip() for b in args.body.split(",") if b.strip()]:
            if body_mode not in BODY_MODES:
                raise SystemExit(f"unknown body {body_mode!r}: choose from {', '.join(BODY_MODES)}")
            r = run_dataset(name, methods, args, body_mode)
            if r is not None:
                results.append(r)
    if not args.markdown:
        print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, numpy {np.__version__}")
    fmt = {"frames/s": ",.0f", "H-PE": ".4f", "GP": ".4f", "MPJPE": ".2f"}
    for r in results:
        what = BODY_TITLES[r["body"]]
        caught = "; smoothing " + (args.smoothing if args.smoothing == "auto" else f"{args.smoothing:g} s")
        if args.overlap != pipeline.DEFAULT_OVERLAP:
            caught += f"; {args.overlap} network windows per frame"
        if args.capture:
            c = args.capture
            caught += (f"; trackers captured at {c['rate']:g} Hz, noise {c['pos_mm']:g} mm / {c['rot_deg']:g} deg, "
                       f"timestamp jitter {c['time_ms']:g} ms, resampled")
        print(f"\n{r['name']}, {what}: {r['clips']} clips, {r['frames']} frames at 30 fps "
              f"({os.path.basename(r['source'])}){caught}")
        rows = [(labels.get(m, m), {(f"{k} [{UNITS[k]}]" if UNITS.get(k) else k): v for k, v in row.items()
                                    if k in UNITS})
                for m, row in r["rows"] if m in main_methods]
        cols = [f"{k} [{UNITS[k]}]" if UNITS[k] else k for k in COLUMNS]
        f2 = {(f"{k} [{UNITS[k]}]" if UNITS.get(k) else k): v for k, v in fmt.items()}
        print(metrics.format_table(rows, cols, formats=f2))
        if args.per_class:
            print_class_table(r)
        if set_names:
            print_tracker_table(r, set_names, what)
    return results


if __name__ == "__main__":
    main()
