"""3D keypoints → an animated 22-joint body, by HybrIK twist-and-swing IK.  No bpy.

    from blender_manikin.core.solve import SolveSettings, solve_recording
    outcome = solve_recording("take/output_data", SolveSettings(fps=30.0, smoothing="auto"))
    outcome.result          # PoseResult, as a tracker solve gives (same writers, same armature)

Stages (each a function, for tests and benchmarks):

1. read (:func:`.io_keypoints.read_keypoints`): metres, Blender axes, NaN = missing;
2. :func:`.keypoint_sides.fix_side_swaps`: legs' and arms' points that took the other side's
   labels for a few frames (a markerless detector's left/right swaps) get their own back;
   :func:`.keypoint_spikes.remove_spikes`: samples far off their point's local median (a
   detector's one- to three-frame misplacements) set missing;
   :func:`bridge_gaps`: every point's missing stretches filled by linear interpolation in
   time (held at the ends), reported as :class:`.resample.Gap` s;
3. smoothing: by default (``smoothing="auto"``) :func:`.smoothing.smooth_auto`: each point's own
   Savitzky-Golay filter, chosen by Stein's unbiased risk estimate from the noise measured on
   it; or :func:`.smoothing.smooth`, one quadratic Savitzky-Golay window of ``smoothing`` seconds (zero lag);
4. resampling to the solve's frame rate (linear in time);
5. :func:`.keypoint_layouts.body22_from_keypoints`: the 22 joints and the orientations the
   layout shows;
6. :func:`size_body`: bone lengths from the median over the take, left and right averaged, on
   the rest directions of :func:`.skeleton.make_body`, so bones never stretch (a spine the
   layout does not measure: to the straight trunk's length);
7. :func:`estimate_floor`: the floor height from the lowest foot points; the take is moved so
   the floor is ``z = 0`` (``keypoint_floor="keep"``, :data:`KEYPOINT_FLOORS`: solved so, then
   put back, so that the joints stay at the heights given, e.g. an armature's in its scene);
8. IK (:func:`.hybrik.ik_from_positions`, adaptive by default: each bone aims at its keypoint
   from where the chain actually is; a trunk the layout does not measure is first fitted to the
   hips and shoulders, :func:`rigid_trunk`): limbs through the analytic limb solver, so elbows and
   knees are hinges within their limits and the swivel angles become the usual keyed
   properties; feet contacts (:func:`foot_contacts`) hold planted ankles still and the feet are
   kept above the floor, then the limbs are solved again onto those ankle targets.
"""
from __future__ import annotations

import dataclasses
import time as _time
from dataclasses import dataclass
import numpy as np

from . import hybrik
from . import limb_solver as ls
from .keypoint_sides import fix_side_swaps
from .keypoint_spikes import remove_spikes, spike_threshold
from . import keypoint_layouts as kl
from . import pipeline
from . import rotations as rot
from . import skeleton as sk
from .pose_result import PoseResult
from .resample import Gap, GapReport
from .smoothing import AUTO_FILTERS, parse_smoothing, smooth, smooth_auto, smoothing_note
from .solve import SolveError, SolveOutcome, SolveSettings, parse_floor, trim_span

#: the keypoint solve's floor choices (``SolveSettings.keypoint_floor``): ``"feet"``, the floor
#: found under the feet (:func:`estimate_floor`) becomes z = 0 and the body stands on its shoe
#: soles, the feet kept above it; ``"keep"``, the joints stay at the heights given: the solve runs
#: on the floor found (the feet's contacts are told from it) and the result is moved back by it,
#: the soles lifting nothing and a foot through the floor left there: a source whose floor is the
#: scene's own (an armature in the scene)
KEYPOINT_FLOORS = ("feet", "keep")


def parse_keypoint_floor(value) -> str:
    """``SolveSettings.keypoint_floor`` checked: one of :data:`KEYPOINT_FLOORS` (None: ``"feet"``)."""
    key = "feet" if value is None else str(value).strip().lower()
    if key not in KEYPOINT_FLOORS:
        raise SolveError(f"keypoint floor {value!r}: expected {' or '.join(KEYPOINT_FLOORS)}")
    return key


#: left / right joint pairs whose bone lengths are averaged
_PAIRS = [(sk.J[f"left_{n}"], sk.J[f"right_{n}"]) for n in
          ("hip", "knee", "ankle", "foot", "collar", "shoulder", "elbow", "wrist")]
#: an ankle slower than this (m/s) and lower than its rest height plus CONTACT_HEIGHT is planted
CONTACT_SPEED = 0.25
CONTACT_HEIGHT = 0.05
#: metres a planted ankle may be held from where its keypoints put it (horizontally, as the
#: tracker solve locks, :data:`.pipeline.LOCK_AXES`); a plant drifting further (a foot rolling
#: onto its toes) is split into successive holds.  Keypoints are measurements: a lock that moved
#: ankles further would trade their accuracy for less sliding than the real foot had
LOCK_MAX_DRIFT = 0.02
#: seconds a held ankle eases into and out of each plant.  Shorter than the tracker solve's
#: (:data:`.pipeline.CONTACT_BLEND_S`, 0.2 s, which hides the network's ankle noise): keypoints
#: are measurements, and a longer ease holds the ankle off them longer (coco17, 15 clips, clean
#: keypoints, benchmarks/bench_keypoints.py: 0.133 / 0.2 s: Bandai JPE 0.26 / 0.35 cm, jitter
#: 1.01 / 1.08; HDM05 JPE 0.37 / 0.41 cm)
CONTACT_BLEND_S = 4 / 30


# --------------------------------------------------------------------------
def bridge_gaps(time, points, names=None):
    """Fill each point's missing stretches (NaN) by linear interpolation in time; before its
    first and after its last sample it is held.

    time ``(T,)`` seconds; points ``(T, K, 3)``.  Returns ``(filled (T, K, 3), gaps)``: gaps a
    list of :class:`.resample.Gap` (device = the point's name, reason ``lost`` / ``start`` /
    ``end``).  A point never seen stays NaN (the caller decides).
    """
    X = np.array(points, np.float64, copy=True)
    t = np.asarray(time, np.float64)
    gaps = []
    for k in range(X.shape[1]):
        ok = np.isfinite(X[:, k]).all(-1)
        if ok.all() or not ok.any():
            continue
        for a in range(3):
            X[~ok, k, a] = np.interp(t[~ok], t[ok], X[ok, k, a])
        name = names[k] if names is not None else str(k)
        miss = np.nonzero(~ok)[0]
        starts = np.concatenate([[0], np.nonzero(np.diff(miss) > 1)[0] + 1])
        ends = np.concatenate([starts[1:], [len(miss)]])
        for s, e in zip(starts, ends):
            a, b = miss[s], miss[e - 1]
            reason = "start" if a == 0 else ("end" if b == len(t) - 1 else "lost")
            gaps.append(Gap(name, float(t[max(a - 1, 0)]), float(t[min(b + 1, len(t) - 1)]), reason, int(b - a + 1)))
    return X, gaps


def resample_points(time, X, fps, t0=None):
    """``(times (N,), X (N, ...))``: ``X`` ``(T, ...)`` linearly interpolated onto a grid at ``fps``
    from ``t0`` (default the first time) to the last time."""
    t = np.asarray(time, np.float64)
    t0 = float(t[0]) if t0 is None else float(t0)
    n = int(np.floor((t[-1] - t0) * fps + 1e-6)) + 1
    grid = t0 + np.arange(n) / float(fps)
    flat = np.asarray(X, np.float64).reshape(len(t), -1)
    out = np.empty((n, flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.interp(grid, t, flat[:, c])
    return grid, out.reshape((n,) + np.shape(X)[1:])


#: the spine bones pelvis → spine1 → spine2 → spine3 → neck
_SPINE = [sk.J["spine1"], sk.J["spine2"], sk.J["spine3"], sk.J["neck"]]
#: percentile of the pelvis-to-neck distance a derived spine is sized to (see :func:`size_body`)
SPINE_PERCENTILE = 90


def size_body(P, height=None, derived_spine=False, sole=None) -> sk.Body:
    """A :class:`.skeleton.Body` with the bone lengths of ``P`` ``(T, 22, 3)`` metres.

    Each bone's length is its median over the frames, left and right averaged; directions and
    the rest pose are those of :func:`.skeleton.make_body` (limbs straight along the axes, feet
    on the floor), so the limb solver's hinge axes hold.  height: scales the body to that
    stature (metres; the head joint 0.831 statures above the ankles, :data:`.skeleton.PROPORTIONS`).
    sole: metres of shoe sole the feet stand on (None: :data:`.skeleton.SOLE`).

    derived_spine: the spine joints are guesses on the line from the pelvis to the neck (layouts
    with no spine points): that line shortens when the trunk bends and never grows longer than
    the straight spine, so the spine bones are scaled together to the
    :data:`SPINE_PERCENTILE` th percentile of the pelvis-to-neck distance (a median would size
    the spine of a take spent bending over too short for its upright frames)."""
    L = np.linalg.norm(P[:, 1:] - P[:, sk.PARENTS[1:]], axis=-1)
    L = np.concatenate([[0.0], np.nanmedian(L, axis=0)])
    for a, b in _PAIRS:
        L[a] = L[b] = 0.5 * (L[a] + L[b])
    if not np.all(np.isfinite(L[1:])) or np.any(L[1:] <= 1e-4):
        raise SolveError("cannot size the body: some bones have no length in the keypoints")
    tmpl = sk.make_body(1.75)
    dirs = tmpl.offsets / np.maximum(tmpl.bone_lengths()[:, None], 1e-12)
    off = dirs * L[:, None]
    # the branching joints' children (hips and spine under the pelvis; neck and collars on the
    # upper chest) where the take has them: their layout is the performer's (or the capture's)
    for j, (lc, rc, up) in _BRANCHES.items():
        measured = _branch_offsets(P, j, lc, rc, up)
        if measured is not None:
            for c, o in measured.items():
                off[c] = o
    if derived_spine:
        chord = np.linalg.norm(P[:, sk.J["neck"]] - P[:, sk.J["pelvis"]], axis=-1)
        straight = np.nanpercentile(chord, SPINE_PERCENTILE)
        now = np.linalg.norm(off[_SPINE], axis=-1).sum()
        if np.isfinite(straight) and now > 0:
            off[_SPINE] *= straight / now
    rel = np.zeros((sk.NUM_JOINTS, 3))
    for j in range(1, sk.NUM_JOINTS):
        rel[j] = rel[sk.PARENTS[j]] + off[j]
    ankle = min(rel[sk.J["left_ankle"], 2], rel[sk.J["right_ankle"], 2])
    head_above_ankle = rel[sk.J["head"], 2] - ankle
    H = float(sk.stature_from_head_above_ankles(head_above_ankle))
    if height:
        s = float(height) / H
        off, rel, ankle, H = off * s, rel * s, ankle * s, float(height)
    sole = sk.sole_or_default(sole)
    root = np.array([0.0, 0.0, -ankle + sk.PROPORTIONS["ankle_height"] * H + sole])
    body = sk.Body.from_offsets(off, root, stature=H, sole=sole)
    return body


#: branching joint -> (left child, right child, the child along the trunk)
_BRANCHES = {sk.J["pelvis"]: (sk.J["left_hip"], sk.J["right_hip"], sk.J["spine1"]),
             sk.J["spine3"]: (sk.J["left_collar"], sk.J["right_collar"], sk.J["neck"])}


def _branch_offsets(P, j, lc, rc, up):
    """Rest offsets ``{child: (3,)}`` of joint ``j``'s three children, metres: the median of their
    offsets in a frame of ``j`` (+X from the right child to the left one, +Z towards the trunk
    child, so the trunk child sits straight above), left and right made mirror images.  None
    when the take gives no frame."""
    R = rot.frame_from_axes(P[:, lc] - P[:, rc], P[:, up] - P[:, j], "xz")
    rel = np.einsum("tji,tkj->tki", R, P[:, [lc, rc, up]] - P[:, j:j + 1])
    ok = np.isfinite(rel).all(axis=(1, 2))
    if not ok.any():
        return None
    o = np.median(rel[ok], axis=0)                                    # (3 children, 3)
    side = 0.5 * (o[0] + o[1] * np.array([-1.0, 1.0, 1.0]))           # left, right mirrored
    return {lc: side, rc: side * np.array([-1.0, 1.0, 1.0]), up: np.array([0.0, 0.0, o[2, 2]])}


def estimate_floor(P, body: sk.Body):
    """The floor's height (metres): where the feet's lowest points are when the feet are down.

    Per frame, the lowest of each ankle less its rest height and each ball of the foot less
    its rest height; the floor is the 10th percentile over the take (robust to noise and to
    frames where a point dipped)."""
    rest = body.rest_positions()
    low = []
    for j in ("left_ankle", "right_ankle", "left_foot", "right_foot"):
        low.append(P[:, sk.J[j], 2] - rest[sk.J[j], 2])
    low = np.min(np.stack(low, -1), -1)
    return float(np.nanpercentile(low, 10))


def foot_contacts(ankle_pos, body: sk.Body, fps):
    """``(T, 2)`` float 0/1: planted where an ankle moves slower than :data:`CONTACT_SPEED`
    (m/s, horizontally, over three frames) and stays within :data:`CONTACT_HEIGHT` of its rest
    height.  ankle_pos ``(T, 2, 3)`` metres with the floor at ``z = 0``."""
    a = np.asarray(ankle_pos, np.float64)
    v = np.zeros(a.shape[:2])
    if a.shape[0] > 2:
        v[1:-1] = np.linalg.norm(a[2:, :, :2] - a[:-2, :, :2], axis=-1) * fps / 2.0
        v[0], v[-1] = v[1], v[-2]
    rest_h = body.rest_positions()[[sk.J["left_ankle"], sk.J["right_ankle"]], 2]
    return ((v < CONTACT_SPEED) & (a[..., 2] < rest_h + CONTACT_HEIGHT)).astype(np.float64)


def _with_given_orientations(b22: kl.Body22, names, Q):
    """``b22`` with the orientations a source gives itself (``names``, joint names; ``Q``
    ``(T, len(names), 4)`` their quaternions on the solve's grid, linearly interpolated, w x y z)
    in place of those the layout shows or not: their joints' twist no longer rest twist."""
    if not names:
        return b22
    R = rot.quat_to_matrix(rot.normalize(Q))
    told = set()
    for k, name in enumerate(names):
        b22.end_rot[sk.J[name]] = R[:, k]
        told |= {name, name.replace("_ankle", "_foot")}
    b22.no_twist = tuple(n for n in b22.no_twist if n not in told)
    return b22


def _finite_orientations(b22: kl.Body22):
    """Drop orientations whose points were never seen (after bridging they stay NaN)."""
    no_twist = list(b22.no_twist)
    for j in list(b22.end_rot):
        if not np.isfinite(b22.end_rot[j]).all():
            del b22.end_rot[j]
            no_twist.append(sk.JOINT_NAMES[j] if j != sk.J["head"] else "head")
    b22.no_twist = tuple(dict.fromkeys(no_twist))
    return b22


#: weight of the spine's direction against the two hips' in the pelvis fit of :func:`rigid_trunk`
#: (the hips are measured; the spine is the trunk's line, only its tilt about the hip axis counts)
SPINE_WEIGHT = 0.05


def _procrustes(rest, target, w):
    """Rigid ``(R (T, 3, 3), p (T, 3))`` minimising ``Σ_i w_i |p + R rest_i - target_i|²``.

    rest ``(K, 3)``, target ``(T, K, 3)``, w ``(K,)``."""
    w = np.asarray(w, np.float64) / np.sum(w)
    rc = w @ rest                                                   # (3,)
    tc = np.einsum("k,tki->ti", w, target)                          # (T, 3)
    R = hybrik.kabsch(rest - rc, target - tc[:, None], w, directions=False)
    return R, tc - np.einsum("tij,j->ti", R, rc)


def rigid_trunk(P, body: sk.Body):
    """Trunk targets a rigid trunk of ``body`` can meet, for layouts that measure the hips and the
    shoulders but not the spine (COCO, MediaPipe, OpenPose, Human3.6M).

    The spine, neck and collar joints :func:`.keypoint_layouts.body22_from_keypoints` places
    are guesses along the trunk's line, and the distances between them change as the trunk
    bends, which no rigid skeleton follows: aiming each bone at them leaves the shoulders
    1-2 cm off.  Instead the trunk is fitted to the measured points:

    1. the pelvis turns so the hips land on theirs (the spine's direction, weighted
       :data:`SPINE_WEIGHT`, only sets the tilt about the hip axis);
    2. the chest (spine3 with the collars at rest) is the rigid fit (Procrustes) of the two
       shoulders and the neck point to the body's rest shoulders and neck;
    3. spine2 is placed so the two spine bones from spine1 (where the pelvis puts it) reach the
       chest: on their circle, bent towards the back (a trunk bending forwards curves the back);
       a chest further than the straight spine reaches leaves it straight.

    P ``(T, 22, 3)`` metres; returns ``(P', pelvis world rotation (T, 3, 3))``: P with spine2,
    spine3, the neck and the collars moved (the hips, shoulders, head and limbs untouched).
    The IK then meets the hips exactly and the shoulders within what a rigid chest and the
    collars' swing allow."""
    J = sk.J
    off = body.offsets
    P = np.array(P, np.float64, copy=True)
    pel, s1, s2, s3 = J["pelvis"], J["spine1"], J["spine2"], J["spine3"]
    hips = [J["left_hip"], J["right_hip"]]
    R0 = hybrik.kabsch(off[hips + [s1]], P[:, hips + [s1]] - P[:, pel:pel + 1], weights=[1.0, 1.0, SPINE_WEIGHT])
    # the chest: spine3 and what hangs from it at rest (collars straight, so the shoulders are
    # collar + shoulder offsets away)
    chest = [J["left_shoulder"], J["right_shoulder"], J["neck"]]
    rest = np.stack([off[J["left_collar"]] + off[J["left_shoulder"]],
                     off[J["right_collar"]] + off[J["right_shoulder"]], off[J["neck"]]])
    R3, p3 = _procrustes(rest, P[:, chest], [1.0, 1.0, 1.0])
    # the spine: spine1 where the pelvis puts it, spine2 on the circle of the two bones to spine3
    a1 = P[:, pel] + np.einsum("tij,j->ti", R0, off[s1])
    l2, l3 = np.linalg.norm(off[s2]), np.linalg.norm(off[s3])
    d = p3 - a1
    dn = np.maximum(np.linalg.norm(d, axis=-1), 1e-9)
    u = d / dn[:, None]
    along = np.clip((l2 * l2 - l3 * l3 + dn * dn) / (2.0 * dn), -l2, l2)
    radius = np.sqrt(np.maximum(l2 * l2 - along * along, 0.0))
    reach = dn < l2 + l3
    back = np.einsum("tij,j->ti", R0 + R3, [0.0, 1.0, 0.0])        # the body's back (+Y at rest)
    back = rot.normalize(back - np.sum(back * u, -1, keepdims=True) * u)
    P[:, s2] = a1 + np.where(reach[:, None], along[:, None] * u + radius[:, None] * back, l2 * u)
    P[:, s3] = p3
    P[:, J["neck"]] = p3 + np.einsum("tij,j->ti", R3, off[J["neck"]])
    for c in ("left_collar", "right_collar"):
        P[:, J[c]] = p3 + np.einsum("tij,j->ti", R3, off[J[c]])
    return P, R0


def fit_keypoints(P, end_rot, body: sk.Body, fps, adaptive=True, lock_feet=True, derived_spine=False,
                  above_floor=True):
    """IK of the 22 joints ``P`` ``(T, 22, 3)`` (floor at ``z = 0``) onto ``body``: a
    :class:`PoseResult` with contacts and (``above_floor``) the ankles kept above the floor
    (False: where the keypoints put them, a foot below the floor left there).  derived_spine: the
    layout has no spine points (:func:`rigid_trunk` fits the trunk to the hips and shoulders)."""
    if derived_spine:
        P, pelvis_rot = rigid_trunk(P, body)
        end_rot = dict(end_rot)
        end_rot.setdefault(sk.J["pelvis"], pelvis_rot)
    ik = hybrik.ik_from_positions(P, body, end_rot=end_rot, adaptive=adaptive, aim_chain=True,
                                  within_limits=True, straight=ls.STRAIGHT_NOISY)
    ank = [sk.J["left_ankle"], sk.J["right_ankle"]]
    contacts = foot_contacts(ik.positions[:, ank], body, fps)
    targets = ik.positions[:, ank]
    if lock_feet:
        targets = pipeline.lock_planted_feet(targets, contacts, threshold=0.5, axes=pipeline.LOCK_AXES,
                                             blend_s=CONTACT_BLEND_S, fps=fps,
                                             max_drift=LOCK_MAX_DRIFT)
    if above_floor:
        targets = pipeline.keep_feet_above_floor(targets, ik.world_rot[:, ank], body)
    # the limbs reach the chain the keypoints give (aim_chain): the first pass's reach error is
    # what the summary reports; a planted or lifted ankle the leg misses by a few millimetres
    # is the lock's own doing, not a sizing problem the user should check
    reach = ik.reach_error
    moved = np.abs(targets - ik.positions[:, ank]).max() > 1e-9
    if moved:
        # again from the first pass's own joints (it reproduces them exactly), the ankles moved:
        # the legs reach the new ankle targets, the knees keep their swivel
        Q = ik.positions.copy()
        Q[:, ank] = targets
        er = dict(end_rot)
        for j in ank + [sk.J["left_wrist"], sk.J["right_wrist"]]:
            er[j] = ik.world_rot[:, j]
        ik = hybrik.ik_from_positions(Q, body, end_rot=er, adaptive=True, within_limits=True,
                                      straight=ls.STRAIGHT_NOISY)
    return PoseResult(fps=float(fps), body=body, local_rot=ik.local_rot, root_pos=ik.root_pos,
                      swivel=ik.swivel, contacts=contacts > 0.5, reach_error=reach)


@dataclass
class PreparedKeypoints:
    """The 22 joints a keypoint take gives, ready for IK (:func:`prepare_keypoints`).

    times ``(T,)`` seconds on the solve's grid; P ``(T, 22, 3)`` metres, Blender axes, the floor
    moved to z = 0; b22: the :class:`.keypoint_layouts.Body22` (orientations, joints without
    twist); body: the sized :class:`.skeleton.Body`; floor: the floor height found in the
    keypoints (metres); gaps: the bridged :class:`.resample.Gap` s; never: points never seen;
    derived_spine: the layout has no spine points (:func:`rigid_trunk` applies); windows: with
    ``smoothing="auto"``, the window (seconds, 0: none) :func:`.smoothing.smooth_auto` chose for each point
    seen, else None; sides: the :class:`.keypoint_sides.SideSwaps` undone (None: not looked for);
    spikes: ``(T_read, K)`` bool, the samples removed as spikes (None: not looked for); stray_upper:
    upper-body samples dropped from a lower-body take (:func:`.keypoint_layouts.drop_stray_upper_body`)."""
    times: np.ndarray
    P: np.ndarray
    b22: kl.Body22
    body: sk.Body
    floor: float
    gaps: list
    never: list
    derived_spine: bool = False
    windows: list = None
    sides: object = None
    spikes: np.ndarray = None
    stray_upper: int = 0


def prepare_keypoints(rec, fps, smoothing, height=None, max_frames=None, sole=None,
                      fix_sides=True, despike=True, start=None, end=None) -> PreparedKeypoints:
    """Stages 2-7 of the module docstring on a :class:`.io_keypoints.KeypointRecording`: left/right
    label swaps undone (``fix_sides``), spikes removed (``despike``), gaps bridged, smoothed
    (``smoothing``: ``"auto"`` for :func:`.smoothing.smooth_auto`, else a Savitzky-Golay window
    in seconds, 0: none), resampled to ``fps``, the 22 joints placed, the body sized (scaled to
    ``height`` metres when given, on ``sole`` metres of shoe sole, None: :data:`.skeleton.SOLE`)
    and the floor moved to z = 0.  start / end: the part kept, seconds from the first sample
    (:func:`.solve.trim_span`; cut after smoothing, so the filter sees the motion around it).  Raises
    :class:`.solve.SolveError` when a joint cannot be placed (a point it needs was never seen)."""
    lay = kl.LAYOUTS[rec.layout]
    rate = 1.0 / float(np.median(np.diff(rec.time)))
    points, sides = fix_side_swaps(rec.points, lay.points) if fix_sides else (rec.points, None)
    points, spikes = remove_spikes(points, rate) if despike else (points, None)
    # a lower-body take's stray upper-body samples (a detector's false wrist) dropped before the
    # gaps are bridged, which would hold them over the whole take
    points, stray_upper = kl.drop_stray_upper_body(points, lay)
    X, gaps = bridge_gaps(rec.time, points, lay.points)
    never = [lay.points[k] for k in range(X.shape[1]) if not np.isfinite(X[:, k]).any()]
    smoothing = parse_smoothing(smoothing)
    chosen = None
    if smoothing == "auto":
        X, choice = smooth_auto(X, rate)
        chosen = [AUTO_FILTERS[c][0] for k, c in enumerate(choice) if lay.points[k] not in never]
    elif smoothing:
        X = smooth(X, rate, smoothing)
    given = list(rec.orientations or {})          # a source's own orientations (an armature's bones)
    Qg = np.stack([rot.quat_continuous(rot.matrix_to_quat(rot.orthonormalize(rec.orientations[j])), axis=0)
                   for j in given], 1) if given else np.zeros((len(rec.time), 0, 4))
    times, X = resample_points(rec.time, X, fps)
    _, Qg = resample_points(rec.time, Qg, fps)
    span = trim_span(times, start, end)
    if span is not None:
        times, X, Qg = times[span[0]:span[1]], X[span[0]:span[1]], Qg[span[0]:span[1]]
    if max_frames and len(times) > max_frames:
        times, X, Qg = times[:max_frames], X[:max_frames], Qg[:max_frames]
    b22 = _with_given_orientations(kl.body22_from_keypoints(X, lay), given, Qg)
    b22 = _finite_orientations(b22)
    P = b22.positions
    bad = [sk.JOINT_NAMES[j] for j in range(sk.NUM_JOINTS) if not np.isfinite(P[:, j]).all()]
    if bad:
        raise SolveError(f"{rec.source}: joint(s) {', '.join(bad)} cannot be placed: point(s) "
                         f"{', '.join(never) or '?'} never seen")
    derived_spine = not lay.has_spine
    body = size_body(P, height, derived_spine=derived_spine, sole=sole)
    floor = estimate_floor(P, body)
    return PreparedKeypoints(times, P - np.array([0.0, 0.0, floor]), b22, body, floor, gaps, never, derived_spine,
                             chosen, sides, spikes, stray_upper)


def solve_keypoints(source, settings: SolveSettings | None = None, progress=None) -> SolveOutcome:
    """Solve keypoints (a path :func:`.io_keypoints.read_keypoints` reads, or a
    :class:`.io_keypoints.KeypointRecording`) into a :class:`SolveOutcome` whose ``result`` is
    a :class:`PoseResult` like a tracker solve's; ``info`` names the joints with no twist
    information, the floor and the smoothing.

    settings (:class:`.solve.SolveSettings`): fps (None: the file's rate), keypoint_layout,
    units, up, rate, mapping (see :func:`.io_keypoints.read_keypoints`), smoothing (``"auto"`` or
    a window in seconds, see :func:`prepare_keypoints`),
    ik (``adaptive`` / ``naive``), height (scales the measured body to this stature, metres; None:
    a TRC's subject parameter file's ``Height`` where it has one, ``subject_params``),
    max_frames, fix_sides, despike, keypoint_floor (``"feet"``: the floor found under the feet,
    :func:`estimate_floor`, moved to z = 0; ``"keep"``: the result put back by it, so the joints
    stay at the heights given, the shoe soles then lifting nothing).  Tracker options (axes,
    offsets, calibration, floor) do not apply.
    progress: ``(fraction, stage)`` callback; an exception raised from it stops the solve."""
    from .io_keypoints import KeypointRecording, read_keypoints
    s = settings or SolveSettings()
    if str(s.ik).lower() not in ("adaptive", "naive"):
        raise SolveError(f"ik {s.ik!r}: expected adaptive or naive")
    adaptive = str(s.ik).lower() == "adaptive"
    keep = parse_keypoint_floor(s.keypoint_floor) == "keep"
    report = progress or (lambda f, stage=None: None)
    out = SolveOutcome()
    t = _time.perf_counter()
    if isinstance(source, KeypointRecording):
        rec = source
    else:
        report(0.0, "reading keypoints")
        rec = read_keypoints(source, layout=s.keypoint_layout, units=s.units, up=s.up, rate=s.rate,
                             mapping=s.mapping, subject_params=s.subject_params,
                             person=getattr(s, "person", None), person_axis=getattr(s, "person_axis", None))
    out.recording = rec
    out.timings["read"] = _time.perf_counter() - t
    t = _time.perf_counter()
    report(0.1, "preparing keypoints")
    fps = float(s.fps) if s.fps else 1.0 / float(np.median(np.diff(rec.time)))
    smoothing = parse_smoothing(s.smoothing)
    height = s.height or rec.metadata.get("subject_height")     # typed, else the subject file's stature
    prep = prepare_keypoints(rec, fps, smoothing, height=height, max_frames=s.max_frames, sole=s.sole,
                             fix_sides=s.fix_sides, despike=s.despike, start=s.start, end=s.end)
    lay, b22, never = kl.LAYOUTS[rec.layout], prep.b22, prep.never
    out.report = GapReport(fps=fps, t0=float(prep.times[0]), t_end=float(prep.times[-1]),
                           num_frames=len(prep.times), devices=lay.points, gaps=prep.gaps)
    out.body, out.floor = prep.body, prep.floor
    out.timings["prepare"] = _time.perf_counter() - t
    report(0.4, "solving")
    t = _time.perf_counter()
    result = fit_keypoints(prep.P, b22.end_rot, prep.body, fps, adaptive=adaptive, derived_spine=prep.derived_spine,
                           above_floor=not keep)
    result.t0 = float(prep.times[0])
    if keep:                    # solved on the floor found (contacts, feet above it), put back where given
        result = dataclasses.replace(result, root_pos=np.asarray(result.root_pos, np.float64)
                                     + np.array([0.0, 0.0, prep.floor]), _fk=None)
    out.result = result
    out.timings["solve"] = _time.perf_counter() - t
    if not s.height and height:
        out.info.append(f"stature {height:.3f} m from the subject parameter file")
    told = smoothing_note(smoothing, prep.windows, "point")
    out.info.append(f"keypoints: {'adaptive' if adaptive else 'naive'} HybrIK, floor at {prep.floor:+.3f} m "
                    + ("not moved" if keep else "moved to 0"))
    out.info.append(told)
    if keep:
        out.info.append(f"floor at {prep.floor:+.3f} m under the feet, heights kept as given (the shoe soles "
                        f"lift nothing, the feet are not kept above it)")
    if s.start is not None or s.end is not None:
        out.info.append(f"trimmed to {prep.times[0] - rec.time[0]:.2f}-{prep.times[-1] - rec.time[0]:.2f} s")
    rate = 1.0 / float(np.median(np.diff(rec.time)))          # the file's samples per second
    swapped = prep.sides.note(rate) if prep.sides is not None else None
    if swapped:
        out.info.append(swapped)
    if prep.spikes is not None and prep.spikes.any():
        out.info.append(f"spikes removed: {int(prep.spikes.sum())} sample(s) of "
                        f"{int(prep.spikes.any(0).sum())} point(s) off their neighbours by "
                        f"{100 * spike_threshold(rate):.0f} cm or more (bridged)")
    if parse_floor(s.floor) != 0.0:
        out.info.append(f"the floor setting ({s.floor!r}) is for trackers: keypoints find the floor under the feet")
    if b22.lower_body:
        legs = sk.PROPORTIONS["thigh"] + sk.PROPORTIONS["shank"]
        sized = ("the stature given" if height else
                 f"the stature estimated from the legs' length (hip to ankle taken as {100 * legs:.0f}% of it: "
                 f"long or short legs for the body's height make it off: --height, or a .mp / .vsk Height, sets it)")
        upright = (f"tilted forwards and back with the pelvis markers (ASIS, PSIS), "
                   f"{kl.PELVIS_NEUTRAL_TILT_DEG:.0f}\N{DEGREE SIGN} of anterior tilt taken as upright"
                   if b22.pelvis_tilt else "upright")
        out.info.append(f"lower body only: the trunk, arms and head follow the pelvis at rest (the trunk "
                        f"square to the pelvis, turned and tilted sideways with the hips, {upright}; the arms hanging "
                        f"{kl.ARM_DROP_DEG:.0f}\N{DEGREE SIGN} below horizontal), {sized}"
                        + (f"; {prep.stray_upper} stray upper-body sample(s) left out (seen on at most "
                           f"{100 * kl.STRAY_UPPER_SHARE:.0f}% of the frames: a detector's false positives)"
                           if prep.stray_upper else ""))
    if b22.resting_arms:
        out.info.append(f"arm(s) never seen: the {' and '.join(b22.resting_arms)} arm(s) hang at rest from the "
                        f"shoulder ({kl.ARM_DROP_DEG:.0f}\N{DEGREE SIGN} below horizontal, elbow straight), "
                        f"following the chest")
    if b22.straight_forearms:
        out.info.append(f"wrist(s) never seen: the {' and '.join(b22.straight_forearms)} forearm(s) continue the "
                        f"upper arm, straight")
    if b22.no_twist:
        out.info.append(f"no twist information: {', '.join(b22.no_twist)} (rest twist)")
    if never:
        out.info.append(f"point(s) never seen: {', '.join(never)}")
    report(1.0, "done")
    return out
