"""Inference: tracker targets + body → full-body pose (MANIKIN).  No bpy, no torch.

:func:`solve` runs, for T frames at any fps:

1. resample the head and hand targets to the network's fps (contract) and
   cut them into centred windows (stride W/2), batched through onnxruntime
   (a causal model, ``train --causal``: one window per frame, ending at it);
2. decode every window from its canonical frame and blend overlapping
   windows (weights rising from each window's ends to its centre,
   :func:`window_blend_weights`; 6D rotations and (cos, sin) averaged, then
   re-normalised); filter the rotations and swivel angles in time (Gaussian,
   :data:`NETWORK_SMOOTH_S`); resample back to the scene frames;
3. torso FK from the predicted root orientation and torso rotations, placed
   so the head joint lands exactly on its target;
4. feet: predicted ankle poses lifted so no foot sinks into the floor (ball
   and heel at their standing height, :func:`keep_feet_above_floor`),
   planted while the predicted contact probability is above 0.8 (horizontal
   position locked over the contact, blended in and out; the height stays
   the network's, which keeps the knee consistent with the predicted hips;
   a plant never holds the ankle more than 5 cm from the prediction), or
   taken from foot trackers when the recording has them;
5. the analytic limb solver for the four limbs with the predicted swivel
   angles: hands land exactly on their targets (when an arm cannot reach,
   or the hand is closer than the elbow folds, the collar is swung towards
   or away from the target first, up to 25°) and legs on the feet; a
   predicted swivel that would turn the upper arm or thigh beyond the
   shoulder's or hip's axial range is moved to the limit
   (:func:`.limb_solver.solve_limbs_within_limits`).

Shapes: targets ``(T, 3)`` positions (metres, Blender axes, floor z = 0) and
``(T, 3, 3)`` orientations per device; results in :class:`PoseResult`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from . import features
from . import limb_solver as ls
from .plain import shown
from . import rotations as rot
from .devices import REQUIRED_DEVICES
from .pose_result import PoseResult, TrackerTargets
from .runs import runs
from .skeleton import Body, J, NUM_JOINTS, PARENTS, forward_kinematics, mirror_name
from .smoothing import smooth_frames

#: a foot is planted (reported and locked) where the network is this confident
CONTACT_THRESHOLD = 0.8
#: seconds over which a held ankle eases into and out of each plant (smoothstep; capped at half
#: the swing between two plants).  0.13 / 0.2 / 0.3 s (4 / 6 / 9 frames at 30 fps), with
#: LEG_REACH_SMOOTH_S: HDM05 jitter 0.96 / 0.91 / 0.88 (ground truth 0.93), skate 26.3 / 25.2 /
#: 23.9 cm/s, MPJPE 11.76 / 11.76 / 11.77; Bandai held-out MPJPE 5.07 / 5.05 / 5.10 cm, jitter 0.79 /
#: 0.77 / 0.78 (0.80), skate 8.6 / 6.7 / 5.2 cm/s: 0.2 s is the most accurate
CONTACT_BLEND_S = 0.2
#: seconds (Gaussian sigma) of smoothing of the locked ankle paths, so locking adds no jerk
LOCK_SMOOTH_S = 0.05
#: windows each frame is seen by, as :func:`solve`'s ``overlap`` (the panel's *Overlap*, the CLI's
#: ``--overlap``) chooses it: the window stride is the window / overlap.  2 (default: half a
#: window) keeps 10,000 frames/s; 3 and 4 average more windows at 1.5 and 2 times the network
#: time (shipped 60-frame network, calibrated body, :data:`WINDOW_BLEND_POWER` 0.5, feet kept out
#: of the floor, overlap 2 / 3 / 4: HDM05 MPJPE 9.24 / 9.14 / 9.11 cm, knees 16.17 / 15.95 / 15.96;
#: benchmarks/bench_pose.py --overlap; the HDM05 set as one take, best of four back to back,
#: 13,776 / 11,313 / 8,702 frames/s, where an earlier, faster run gave 16,821 / 12,559 / 10,644;
#: before the feet, Bandai 3.32 / 3.31 / 3.31)
OVERLAP_CHOICES = (2, 3, 4)
DEFAULT_OVERLAP = 2
#: which windows the network also sees left/right mirrored (:func:`.features.mirror_inputs`), its
#: outputs mirrored back and averaged with the plain ones: "off", "alternate" (every second window
#: mirrored instead of plain: no extra cost) or "both" (every window both ways: twice the network)
#: (HDM05, calibrated body, three trackers, off / alternate / both: MPJPE 9.62 / 9.56 / 9.47 cm,
#: knees 16.87 / 16.72 / 16.56, jitter 0.84 / 0.83 / 0.83; alternate with a quarter-window stride
#: 9.46; alternate is also ahead for the four- and six-tracker models, DAP and Bandai's held-out takes).
#: A model whose contract records no mirror augmentation runs plain by default: the network-only
#: baseline (benchmarks/models/baseline_fk.onnx) lost with mirrored windows (Bandai 4.21 -> 4.49 cm)
MIRROR_WINDOWS = "alternate"
MIRROR_CHOICES = ("off", "alternate", "both")
#: axes a planted ankle is locked on: x, y stop the sliding; locking z too moved the ankle
#: away from the height the network predicted with the hips and bent the knees wrongly
#: (knees 2.4 cm with z locked, 2.1 cm without, on 60 held-out takes of the benchmark's split)
LOCK_AXES = (0, 1)
#: metres above the floor a planted foot the network leaves hovering is put down from
#: (:func:`settle_planted_feet`; 0: off)
SETTLE_MAX = 0.05
#: seconds (Gaussian sigma) over which the settling is eased, so it adds no jerk
SETTLE_SMOOTH_S = 0.1
#: metres a planted ankle may be held away from where the network puts it; a contact run
#: drifting further is split into successive plants (see :func:`lock_planted_feet`)
LOCK_MAX_DRIFT = 0.05
COLLAR_MAX_SWING = np.radians(25.0)
#: seconds (Gaussian sigma) of the temporal filter on the network's blended predictions
#: (0.1 s, with the smoothstep easing of plants: HDM05 jitter 1.41 -> 0.98, the ground truth 0.93;
#: MPJPE +0.01 cm; benchmarks/bench_pose.py)
NETWORK_SMOOTH_S = 0.1
#: the network outputs it filters with NETWORK_SMOOTH_S: rotations (6D) and swivel (cos, sin);
#: not the contact probabilities, whose edges decide where plants begin and end
SMOOTHED_OUTPUTS = ("root_rot", "torso_rot", "ankle_rot", "swivel_cs", "local_rot")
#: seconds (Gaussian sigma) of the filter on the predicted ankle positions, before the plants
#: are locked and settled: a trade between jitter and foot skating (shipped model, calibrated
#: body; none / 0.05 / 0.1 s: Bandai held-out skate 7.1 / 8.4 / 12.9 cm/s, jitter 0.91 / 0.88 /
#: 0.84 (ground truth 0.80); HDM05 jitter 1.02 (0.03 s) / 0.99 / 0.96 (0.93))
ANKLE_SMOOTH_S = 0.05
#: seconds (Gaussian sigma) of the filter on each leg's hip-to-ankle distance before the limb
#: solve (:func:`soften_leg_reach`: no knee pop where a predicted ankle crosses the leg's reach);
#: with CONTACT_BLEND_S 0.2, none / 0.03 s: HDM05 jitter 0.95 / 0.91 (ground truth 0.93), knees
#: 19.80 / 19.76 cm; Bandai held-out jitter 0.89 / 0.77 (0.80), knees 8.35 / 8.26 cm; MPJPE
#: within 0.005 cm (shipped model, calibrated body)
LEG_REACH_SMOOTH_S = 0.03
#: network windows built, run and decoded at a time (bounds the network's memory on long takes)
NETWORK_WINDOWS_PER_BATCH = 1024
#: shape of the weights overlapping windows are blended with: a triangle (about 0 at a window's
#: ends, 1 at its centre) raised to this power (:func:`window_blend_weights`).  Under 1 the curve is
#: flatter, so a frame's neighbouring window counts more and the blend averages more, while a
#: window's end frames (context on one side only) still weigh least (0.5: 0.13 of the centre's
#: weight for 60 frames), so no seam shows where a window starts.  Triangle (1) / its square
#: root (0.5) / its fourth root (0.25) / flat (0): HDM05, calibrated body, three trackers, MPJPE
#: 9.31 / 9.27 / 9.26 / 9.26 cm, knees 16.25 / 16.19 / 16.18 / 16.19, jitter 0.77 / 0.77 / 0.78 /
#: 0.79 (ground truth 0.93); held-out Bandai 3.33 / 3.32 / 3.32 / 3.31 cm; 2 (a sharper peak): 9.37,
#: Bandai 3.33.  The square root takes the gain without the jitter; with it, also HDM05 captured at
#: 72 Hz 9.36 -> 9.32 cm, true skeleton 8.66 -> 8.63, four trackers 7.22 -> 7.20, six 4.04 -> 4.04,
#: DAP 9.62 -> 9.57 (benchmarks/bench_pose.py)
WINDOW_BLEND_POWER = 0.5
#: scene frames posed at a time by the torso FK, collar and limb stages (bounds their memory);
#: the result does not depend on it (the leg-reach filter looks past the chunk edges)
ASSEMBLY_CHUNK_FRAMES = 8192


def window_blend_weights(W, power=None):
    """``(W,)`` float64 weights of a window's frames in the blend of overlapping windows: the
    triangle ``1 - |2 (i + 0.5) / W - 1|`` (1 / W at both ends, 1 at the centre) to the power
    ``power`` (default :data:`WINDOW_BLEND_POWER`), plus 1e-3 so a frame only one window sees
    (the take's ends) still gets a weight."""
    p = WINDOW_BLEND_POWER if power is None else float(power)
    tri = 1.0 - np.abs((np.arange(W) + 0.5) / W * 2.0 - 1.0)
    return tri ** p + 1e-3


def overlap_windows(overlap) -> int:
    """``overlap`` as an int of :data:`OVERLAP_CHOICES`, or ``ValueError`` saying what is allowed."""
    try:
        n = int(overlap)
    except (TypeError, ValueError):
        n = None
    if n is None or n != overlap or n not in OVERLAP_CHOICES:
        raise ValueError(f"overlap {overlap!r}: choose {', '.join(map(str, OVERLAP_CHOICES))} "
                         f"(windows seeing each frame)")
    return n


class SolveCancelled(Exception):
    """Raised through :func:`solve` when the progress callback asks to stop."""


@dataclass
class NetworkOutput:
    """Per-frame network predictions at the scene rate (world space).

    root_rot (T,3,3); torso_rot (T,6,3,3) local; ankle_pos (T,2,3);
    ankle_rot (T,2,3,3); swivel (T,4) radians; contact (T,2) probability.
    For kind "fk": local_rot (T,21,3,3) instead of torso/ankles/swivel.
    """
    root_rot: np.ndarray
    contact: np.ndarray
    torso_rot: np.ndarray | None = None
    ankle_pos: np.ndarray | None = None
    ankle_rot: np.ndarray | None = None
    swivel: np.ndarray | None = None
    local_rot: np.ndarray | None = None
    notes: list | None = None          # which model(s) solved which frames (the solve summary)


def blend_outputs(outs, weights):
    """One :class:`NetworkOutput` from several models' outputs for the same frames.

    outs: MANIKIN outputs; weights: ``(T,)`` per output, summing to 1 on every frame (see
    :func:`.model_choice.plan_models`).  Rotations are averaged as 6D and re-orthonormalised,
    swivel angles as (cos, sin), positions and contact probabilities linearly."""
    w = [np.asarray(x, np.float64) for x in weights]

    def mix(values, rotation=False):
        acc = 0.0
        for v, wk in zip(values, w):
            v = rot.matrix_to_6d(v) if rotation else v
            acc = acc + v * wk.reshape((-1,) + (1,) * (v.ndim - 1))
        return rot.sixd_to_matrix(acc) if rotation else acc

    cs = mix([np.stack([np.cos(o.swivel), np.sin(o.swivel)], -1) for o in outs])
    return NetworkOutput(root_rot=mix([o.root_rot for o in outs], True),
                         contact=mix([o.contact for o in outs]),
                         torso_rot=mix([o.torso_rot for o in outs], True),
                         ankle_pos=mix([o.ankle_pos for o in outs]),
                         ankle_rot=mix([o.ankle_rot for o in outs], True),
                         swivel=np.arctan2(cs[..., 1], cs[..., 0]))


def blend_rotations(a, b, u):
    """``(T, 3, 3)`` rotations ``a`` → ``b`` by the weight ``u`` ``(T,)`` (slerp; ``a`` at 0, ``b`` at 1)."""
    u = np.asarray(u, np.float64)
    if np.all(u >= 1.0):
        return np.asarray(b, np.float64).copy()
    if np.all(u <= 0.0):
        return np.asarray(a, np.float64).copy()
    return rot.quat_to_matrix(rot.quat_slerp(rot.matrix_to_quat(a), rot.matrix_to_quat(b), u))


def _interp_rows(t_new, t_old, values):
    """Linear interpolation along axis 0 of ``values`` ``(N, ...)`` (vectorised)."""
    values = np.asarray(values, np.float64)
    if len(t_old) == 1:
        return np.repeat(values, len(t_new), 0)
    idx = np.clip(np.searchsorted(t_old, t_new, side="right") - 1, 0, len(t_old) - 2)
    w = np.clip((t_new - t_old[idx]) / (t_old[idx + 1] - t_old[idx]), 0.0, 1.0)
    w = w.reshape((-1,) + (1,) * (values.ndim - 1))
    return values[idx] * (1 - w) + values[idx + 1] * w


def resample_pose_targets(pos, rotm, fps_in, fps_out):
    """Resample ``(T, 3)`` positions and ``(T, 3, 3)`` orientations to ``fps_out``
    over the same time span (linear / slerp).  Returns ``(pos, rot, times_in, times_out)``."""
    T = pos.shape[0]
    t_in = np.arange(T) / fps_in
    n_out = int(np.floor(t_in[-1] * fps_out + 1e-9)) + 1
    t_out = np.arange(n_out) / fps_out
    p = _interp_rows(t_out, t_in, pos)
    q = rot.quat_continuous(rot.matrix_to_quat(rotm))
    idx = np.clip(np.searchsorted(t_in, t_out, side="right") - 1, 0, max(T - 2, 0))
    if T == 1:
        qo = np.repeat(q, n_out, 0)
    else:
        w = np.clip((t_out - t_in[idx]) * fps_in, 0.0, 1.0)
        qo = rot.quat_slerp(q[idx], q[idx + 1], w)
    return p, rot.quat_to_matrix(qo), t_in, t_out


def run_network(targets: TrackerTargets, body: Body, runner, progress=None, stride=None, windows_per_batch=None,
                smooth_s=None, mirror=None, overlap=None):
    """Windows → onnxruntime → blended per-frame :class:`NetworkOutput` at the scene fps.

    stride: frames between window starts at the model's rate (at most one window; default the
    window / ``overlap``); smaller strides average more windows per frame (smoother, slower).
    overlap: how many windows see each frame, one of :data:`OVERLAP_CHOICES` (default
    :data:`DEFAULT_OVERLAP`), so the choice means the same for every model's window.
    windows_per_batch: windows built, run and decoded at a time (default
    :data:`NETWORK_WINDOWS_PER_BATCH`), which bounds the memory on long takes; the windows and
    the order they are blended in do not depend on it, so neither does the result.
    smooth_s: Gaussian sigma in seconds of a temporal filter on the blended predictions (default
    :data:`NETWORK_SMOOTH_S`, the ankle positions :data:`ANKLE_SMOOTH_S`; 0: both off).
    mirror: one of :data:`MIRROR_CHOICES` (default :data:`MIRROR_WINDOWS` for a model trained
    with mirrored windows, else "off"): windows also run as their left/right mirror image,
    averaged back in.

    A causal model (its contract's ``causal``, ``train --causal``) is run as it is trained and
    as a live solver would run it: one window per frame (at the model's rate), ending at that
    frame, whose last output frame is the result (frames before the take's start repeat its first
    frame); ``stride`` and ``overlap`` do not apply and the temporal filter is off, so each frame
    depends only on the targets up to it (within one frame at the model's rate when the scene's
    rate differs), at about W / overlap times the network time of a centred model.  Its mirror
    "alternate" (the default of a model trained mirrored) runs as "both", twice that time: with
    one window per frame, alternating would leave every other frame to the mirror image alone.
    """
    c = runner.contract
    W = c.window
    fps = float(targets.fps)
    if mirror is None:        # by default only a model trained on mirrored windows sees them
        mirror = MIRROR_WINDOWS if getattr(c, "trained_mirrored", False) else "off"
    if mirror not in MIRROR_CHOICES:
        raise ValueError(f"mirror {mirror!r}: choose one of {', '.join(MIRROR_CHOICES)}")
    if any(mirror_name(d) not in c.devices for d in c.devices):
        mirror = "off"                  # a model with a tracker on one side only has no mirror image
    causal = bool(getattr(c, "causal", False))
    if causal and mirror == "alternate":
        # one window per frame: every other frame would be the mirror's alone (a held pose flickered
        # between the two at the model's rate); each frame is averaged with its mirror instead
        mirror = "both"
    pos_m, rot_m = {}, {}
    for d in c.devices:
        if d not in targets.pos:
            raise ValueError(f"the pose model needs a '{d}' tracker; the recording has {list(targets.pos)}")
        pos_m[d], rot_m[d], t_in, t_out = resample_pose_targets(targets.pos[d], targets.rot[d], fps, c.fps)
    N = t_out.shape[0]
    if causal:
        # a causal (live) model: one window per frame, ending at the frame it solves, whose output
        # is the window's last frame; the first frames see the take's first frame repeated before it
        starts = np.arange(N) - (W - 1)
        keep = slice(W - 1, W)
        tri = np.ones(1)
    else:
        if not stride:
            stride = round(W / overlap_windows(DEFAULT_OVERLAP if overlap is None else overlap))
        stride = min(max(int(stride), 1), W)                              # no frame between two windows
        pad = W // 2
        starts = np.arange(-pad, max(N - pad, 1), stride)
        if starts[-1] + W < N:           # a stride over half a window: one more window reaches the last frame
            starts = np.append(starts, N - pad)
        keep = slice(None)
        tri = window_blend_weights(W)
    # Body-conditioned models were trained with the stature defined from the skeleton (head joint
    # 0.871 statures above the ankles, as make_body builds); older ones with the body's own.
    s_net = float(features.stature_from_offsets(body.offsets)) if c.body else body.stature
    body_in = features.body_features(body.offsets, s_net)[None] if c.body else None
    # a multiple of the runner's batch, so onnxruntime sees the same batches whatever the chunking
    per = max(int(windows_per_batch or NETWORK_WINDOWS_PER_BATCH), 1)
    rb = max(int(getattr(runner, "batch", 1) or 1), 1)
    per = max(rb, per // rb * rb)
    acc, wsum = {}, np.zeros(N)
    for b0 in range(0, len(starts), per):
        frames = starts[b0:b0 + per, None] + np.arange(W)[None]                  # (B, W)
        idx = np.clip(frames, 0, N - 1)                                           # edge padding
        wpos = {d: pos_m[d][idx] for d in c.devices}
        wrot = {d: rot_m[d][idx] for d in c.devices}
        stature = np.full(idx.shape[0], s_net)
        x, C, o = features.make_inputs(wpos, wrot, stature, c.fps, devices=c.devices, body=body_in)
        if mirror == "both":
            y2 = runner.predict(np.concatenate([x, features.mirror_inputs(x, c.devices)]))
            y = 0.5 * (y2[:len(x)] + features.mirror_outputs(y2[len(x):], c.kind))
        elif mirror == "alternate":
            odd = (b0 + np.arange(len(x))) % 2 == 1           # window index parity, whatever the chunking
            x[odd] = features.mirror_inputs(x[odd], c.devices)
            y = runner.predict(x)
            y[odd] = features.mirror_outputs(y[odd], c.kind)
        else:
            y = runner.predict(x)
        frames, idx = frames[:, keep], idx[:, keep]
        dec = features.decode_outputs(y[:, keep], C, o, stature, wpos["head"][:, keep], kind=c.kind)
        flat_idx = idx.reshape(-1)
        wts = (tri[None] * ((frames >= 0) & (frames < N))).reshape(-1)
        wsum += np.bincount(flat_idx, wts, minlength=N)
        blocks = {k: (rot.matrix_to_6d(v) if k.endswith("_rot") else v) for k, v in dec.items()}
        for k, v in blocks.items():
            v = v.reshape((flat_idx.shape[0], -1))
            if k not in acc:
                acc[k] = (np.zeros((N, v.shape[1])), dec[k].shape[2:])
            np.add.at(acc[k][0], flat_idx, v * wts[:, None])
        if progress is not None:
            progress(min(b0 + per, len(starts)) / len(starts))
    blended = {k: (a / wsum[:, None]).reshape((N,) + shape[:-2] + (6,) if k.endswith("_rot") else (N,) + shape)
               for k, (a, shape) in acc.items()}
    # the temporal filter is centred (it reads later frames): a causal model's frames are left as is
    sigma = 0.0 if causal else (NETWORK_SMOOTH_S if smooth_s is None else float(smooth_s)) * c.fps
    if sigma > 0:      # a temporal filter on the predicted rotations and swivel angles
        blended = {k: (smooth_frames(v, sigma) if k in SMOOTHED_OUTPUTS else v) for k, v in blended.items()}
    if sigma > 0 and ANKLE_SMOOTH_S > 0 and "ankle_pos" in blended:     # smooth_s=0: no filter at all
        blended["ankle_pos"] = smooth_frames(blended["ankle_pos"], ANKLE_SMOOTH_S * c.fps)

    # back to the scene frame rate
    t_scene = t_in
    up = {k: rot.sixd_to_matrix(_interp_rows(t_scene, t_out, v)) for k, v in blended.items() if k.endswith("_rot")}
    out = NetworkOutput(root_rot=up["root_rot"],
                        contact=np.clip(_interp_rows(t_scene, t_out, blended["contact"]), 0.0, 1.0))
    if c.kind == "manikin":
        out.torso_rot = up["torso_rot"]
        out.ankle_rot = up["ankle_rot"]
        out.ankle_pos = _interp_rows(t_scene, t_out, blended["ankle_pos"])
        cs = _interp_rows(t_scene, t_out, blended["swivel_cs"])
        out.swivel = np.arctan2(cs[..., 1], cs[..., 0])
    else:
        out.local_rot = up["local_rot"]
    return out


def _plant_pieces(path, a, b, tol):
    """Split the contact run ``[a, b)`` of a ``(T, k)`` path into pieces that each stay
    within ``tol`` of their first frame (greedy).  Returns ``[(start, stop), ...]``."""
    pieces, i = [], a
    while i < b:
        # the first frame further than tol, searched in windows that double (linear in the run's
        # length, where scanning the whole rest of the run for every piece was quadratic)
        j, w = b, 64
        lo = i
        while lo < b:
            hi = min(i + w, b)
            far = np.nonzero(np.linalg.norm(path[lo:hi] - path[i], axis=-1) > tol)[0]
            if far.size:
                j = lo + int(far[0])
                break
            lo, w = hi, 2 * w
        pieces.append((i, j))
        i = j
    return pieces


def _median_rows(x):
    """``np.median(x, axis=0)`` of a small ``(n, 3)`` array, n >= 1, by one sort (the same
    values; np.median's general machinery costs more than the sort on a plant's few frames:
    locking the HDM05 set's feet, 17,878 frames, took 0.11 s instead of 0.17-0.21 s)."""
    x = np.sort(x, axis=0)
    n = x.shape[0]
    return x[n // 2] if n % 2 else 0.5 * (x[n // 2 - 1] + x[n // 2])


def lock_planted_feet(ankle_pos, contact, threshold=CONTACT_THRESHOLD, blend_s=None,
                      axes=(0, 1, 2), max_drift=None, fps=30.0):
    """Hold each ankle still while its foot is planted.

    ankle_pos ``(T, 2, 3)``; contact ``(T, 2)`` probabilities (planted above
    ``threshold``).  Over each plant the ankle is held, on ``axes`` (0, 1, 2 =
    x, y, z), at the median of its predicted coordinates over the plant;
    ``blend_s`` seconds (default :data:`CONTACT_BLEND_S`; at least a frame at ``fps`` frames
    per second) on either side ease in and out (smoothstep), each at most half the gap to the foot's
    neighbouring plant so two eases never overlap.  A foot is only ever held where the
    prediction itself stays put: a run over which the predicted ankle moves
    more than ``max_drift`` metres (default :data:`LOCK_MAX_DRIFT`; a slow
    shuffle the network calls "planted") is split into consecutive plants,
    each within ``max_drift`` of the prediction, eased one into the next.
    Returns a new array.
    """
    max_drift = LOCK_MAX_DRIFT if max_drift is None else float(max_drift)
    blend = max(int(round((CONTACT_BLEND_S if blend_s is None else blend_s) * fps)), 1)
    src = np.array(ankle_pos, np.float64, copy=True)
    out = src.copy()
    T = out.shape[0]
    ax = list(axes)
    for k in range(2):
        # every plant piece of this foot, in time order; ``joined``: it continues the previous
        # piece of the same contact run (the ease between them happens inside the run)
        pieces = []
        for a, b in runs(contact[:, k] > threshold):
            for n, (pa, pb) in enumerate(_plant_pieces(src[:, k, ax], a, b, max_drift)):
                if pb - pa >= 2:
                    pieces.append((pa, pb, n > 0))
        for i, (pa, pb, joined) in enumerate(pieces):
            # an ease into or out of a plant takes at most half the swing to the neighbouring plant,
            # so the eases of two plants never overlap (they would fold the swing into a jerk)
            before = pieces[i - 1][1] if i > 0 else -2 * blend
            after = pieces[i + 1][0] if i + 1 < len(pieces) else T + 2 * blend
            b_in = blend if joined else min(blend, (pa - before) // 2)
            b_out = blend if (i + 1 < len(pieces) and pieces[i + 1][2]) else min(blend, (after - pb) // 2)
            anchor = _median_rows(src[pa:pb, k])
            lo, hi = max(pa - b_in, 0), min(pb + b_out, T)
            t = np.arange(lo, hi)
            w = np.clip(np.minimum((t - (pa - b_in - 1)) / (b_in + 1), ((pb + b_out) - t) / (b_out + 1)), 0.0, 1.0)
            w = (w * w * (3.0 - 2.0 * w))[:, None]        # smoothstep: no velocity jump at the edges
            out[lo:hi, k, ax] = out[lo:hi, k, ax] * (1 - w) + anchor[ax] * w
    return out


#: the heel, where the foot meets the floor behind the ankle: as far behind the ankle as this
#: share of the ankle-to-ball distance (a foot is about 4 ankle-to-heel lengths long, the ankle
#: 20 % of it from the heel, the ball 72 %), level with the ball in the rest pose
HEEL_BACK = 0.38
#: metres a foot the network placed may sink into the floor (ball or heel below its standing
#: height) before :func:`keep_feet_above_floor` lifts the ankle.  A few millimetres of a standing
#: foot's predicted pitch lift the ankle by as much (13 cm lever to the ball), and a nearly straight
#: leg then bends 10 degrees for 4 mm; 5 mm keeps standing knees straight (T- and A-pose knee max
#: 0.0 degrees, against 10.6 with 0; benchmarks/bench_plausibility.py).  HDM05 (T-pose body,
#: 72 Hz trackers) MPJPE / ankles: 9.36 / 16.62 cm; 9.37 / 16.63 before the leg-reach filter's
#: ankles were kept out of the floor too, and 9.36 / 16.57 with 0 then; 9.40 / 16.88 before the
#: heel and the ball's standing height were kept (the ball's joint could reach the sole, 2.1 cm
#: lower)
FOOT_SINK = 0.005


def ankle_height_on_floor(ankle_rot, body: Body, floor=0.0, sink=0.0):
    """``(T, 2)`` metres: the lowest ankle height at which each foot, turned by ``ankle_rot``
    ``(T, 2, 3, 3)`` world, keeps its ball (the foot joint) and its heel no lower than ``sink``
    metres below where they are when the body stands in its rest pose on ``floor`` (the flesh
    under them and the :attr:`.Body.sole` included).  A flat foot gives the rest ankle height;
    a foot turned toes up rests on its heel, toes down on its ball, and either way the ankle
    rises.  The heel is :data:`HEEL_BACK` of the ankle-to-ball distance behind the ankle, level
    with the ball in the rest pose."""
    k = [J["left_foot"], J["right_foot"]]
    rest_z = body.rest_positions()[k, 2]                                       # (2,) ball above floor
    ball = body.offsets[k]                                                     # (2, 3) from the ankle
    heel = ball * np.array([-HEEL_BACK, -HEEL_BACK, 1.0])                      # behind, level with it
    need = [floor + rest_z - sink - np.einsum("tkij,kj->tki", ankle_rot, off)[..., 2] for off in (ball, heel)]
    return np.maximum(*need)


def feet_below_floor(ankle_pos, ankle_rot, body: Body, floor=0.0):
    """``(T, 2)`` metres each foot's ball or heel is below its standing height (0 where it is
    not): how far the foot sinks into ``floor``.  ankle_pos ``(T, 2, 3)``, ankle_rot ``(T, 2,
    3, 3)`` world, as :func:`ankle_height_on_floor`."""
    return np.maximum(ankle_height_on_floor(ankle_rot, body, floor) - np.asarray(ankle_pos)[..., 2], 0.0)


def settle_planted_feet(ankle_pos, ankle_rot, contacts, body: Body, fps, floor=0.0, max_lift=None):
    """Put planted feet down on the floor: on frames a foot is planted (``contacts`` ``(T, 2)``
    bool) and its ankle hovers at most ``max_lift`` (default :data:`SETTLE_MAX`) metres above
    where the foot stands on ``floor`` (:func:`ankle_height_on_floor`: its ball and heel at their
    standing height, and the ankle at least at its rest height), the ankle comes down to it; the drop is smoothed over
    :data:`SETTLE_SMOOTH_S` so it eases in and out (:func:`keep_feet_above_floor` runs after it).
    A planted foot held higher than that (on a step, the network unsure) is left.
    ``ankle_pos`` ``(T, 2, 3)`` metres; returns a new array."""
    lift = SETTLE_MAX if max_lift is None else float(max_lift)
    out = np.array(ankle_pos, np.float64, copy=True)
    rest = body.rest_positions()[[J["left_ankle"], J["right_ankle"]], 2]
    stand = np.maximum(ankle_height_on_floor(ankle_rot, body, floor), floor + rest[None])   # (T, 2)
    above = out[..., 2] - stand
    drop = np.where(contacts & (above > 0) & (above <= lift), above, 0.0)
    if out.shape[0] > 1:
        drop = smooth_frames(drop, SETTLE_SMOOTH_S * fps)
    out[..., 2] -= drop
    return out


def keep_feet_above_floor(ankle_pos, ankle_rot, body: Body, floor=0.0):
    """Lift ankle targets so that no foot sinks into ``floor``.

    ankle_pos ``(T, 2, 3)``, ankle_rot ``(T, 2, 3, 3)`` world.  The ball of the foot and the
    heel stay at most :data:`FOOT_SINK` below their standing height
    (:func:`ankle_height_on_floor`: a flat foot keeps its ankle at the rest height, less that),
    and the ankle at least half its rest height.  Returns a new array.
    """
    out = np.array(ankle_pos, np.float64, copy=True)
    min_ankle = 0.5 * body.rest_positions()[[J["left_ankle"], J["right_ankle"]], 2]
    need = np.maximum(ankle_height_on_floor(ankle_rot, body, floor, FOOT_SINK), floor + min_ankle[None])
    out[..., 2] = np.maximum(out[..., 2], need)
    return out


def _torso_fk(root_rot, torso_rot, head_rot, head_pos, body: Body):
    """Torso FK placed so the head joint lands on ``head_pos``.

    Returns ``(local (T,22,3,3) with root, torso and head filled, root_pos
    (T,3), pos (T,22,3), world (T,22,3,3))``; limb joints are at rest below
    their bases until the limb solver replaces them.
    """
    T = root_rot.shape[0]
    local = np.broadcast_to(np.eye(3), (T, NUM_JOINTS, 3, 3)).copy()
    local[:, 0] = root_rot
    local[:, list(features.TORSO_LOCAL_IDX)] = torso_rot
    pos, world = forward_kinematics(local, np.zeros((T, 3)), body)
    pos, world = np.array(pos), np.array(world)
    neck, head = J["neck"], J["head"]
    local[:, head] = np.swapaxes(world[:, neck], -1, -2) @ head_rot
    world[:, head] = head_rot
    root_pos = head_pos - pos[:, head]
    pos += root_pos[:, None]
    return local, root_pos, pos, world


#: the joints that bend the spine towards the head tracker when a pelvis tracker roots the body
SPINE_CHAIN = (J["spine1"], J["spine2"], J["spine3"], J["neck"])


#: FABRIK iterations of :func:`_bend_spine_to_head` (near-straight spines converge slowly: 12 left
#: the head 3-5 mm off on HDM05, 40 about 1 mm)
SPINE_ITERATIONS = 40


def _bend_spine_to_head(local, root_pos, head_pos, head_rot, body: Body, weight):
    """Bend the spine so the head joint reaches its tracker from a pelvis-tracker root.

    With a pelvis tracker the torso hangs from the pelvis, and the network's torso rotations
    may leave the head joint off its tracker.  The chain spine1 → spine2 → spine3 → neck → head
    is solved by FABRIK (Aristidou & Lasenby 2011) from the network's pose, spine1 fixed (it
    hangs from the tracked pelvis) and the head pulled to ``weight`` (``(T,)``, the pelvis
    tracker's weight) of the way to ``head_pos``; each joint of :data:`SPINE_CHAIN` then
    turns by the smallest swing that points its bone where FABRIK put it, so the twist the
    network predicted is kept.  A target further than the straight spine reaches is missed by
    that much.  ``local`` ``(T, 22, 3, 3)`` is updated in place (head rotation kept on
    ``head_rot``).  Returns ``(local, pos, world)``.
    """
    head, neck = J["head"], J["neck"]
    w = np.asarray(weight, np.float64)
    joints = list(SPINE_CHAIN) + [head]                          # spine1 .. neck, head
    lengths = np.linalg.norm(body.offsets[joints[1:]], axis=-1)  # (4,) bones between them
    pos, world = forward_kinematics(local, root_pos, body)
    pos, world = np.array(pos), np.array(world)
    p = pos[:, joints].copy()                                    # (T, 5, 3)
    goal = p[:, -1] + w[:, None] * (head_pos - p[:, -1])
    base = p[:, 0].copy()
    for _ in range(SPINE_ITERATIONS):
        p[:, -1] = goal
        for i in range(len(joints) - 2, -1, -1):
            p[:, i] = p[:, i + 1] + lengths[i, None] * rot.normalize(p[:, i] - p[:, i + 1])
        p[:, 0] = base
        for i in range(1, len(joints)):
            p[:, i] = p[:, i - 1] + lengths[i - 1, None] * rot.normalize(p[:, i] - p[:, i - 1])
    for i, j in enumerate(SPINE_CHAIN):
        c = joints[i + 1]
        cur = np.einsum("tij,j->ti", world[:, j], body.offsets[c])
        new_world = rot.rotation_between(cur, p[:, i + 1] - p[:, i]) @ world[:, j]
        local[:, j] = np.swapaxes(world[:, PARENTS[j]], -1, -2) @ new_world
        pos, world = forward_kinematics(local, root_pos, body)
        pos, world = np.array(pos), np.array(world)
    local[:, head] = np.swapaxes(world[:, neck], -1, -2) @ head_rot
    world[:, head] = head_rot
    return local, pos, world


def _reach_collars(local, pos, world, targets_pos, body: Body, max_swing=COLLAR_MAX_SWING):
    """Swing the collars (≤ ``max_swing``) on frames where a hand is out of the arm's range.

    A hand further than the straight arm reaches swings the shoulder towards
    it; a hand closer to the shoulder than the elbow can fold (hands raised
    beside the head, say) swings the shoulder away from it.  Each time the
    smallest swing that brings the hand into range is used.  Updates
    ``local`` and, on the frames that need it, the collar rotations and
    shoulder positions in ``pos`` / ``world`` (in place).
    """
    L = body.limb_lengths()
    for li, side in ((0, "left"), (1, "right")):
        col, sh = J[f"{side}_collar"], J[f"{side}_shoulder"]
        wrist = targets_pos[li]
        l1, l2 = L[li]
        reach = (l1 + l2) * (1 - 1e-9)
        d_min = np.sqrt(max(l1 ** 2 + l2 ** 2 + 2 * l1 * l2 * np.cos(ls.FLEX_MAX[li]), 0.0)) * (1 + 1e-9)
        dist = np.linalg.norm(wrist - pos[:, sh], axis=-1)
        for kind, mask in (("far", dist > l1 + l2 + 1e-9), ("close", dist < d_min - 1e-9)):
            if not mask.any():
                continue
            f = np.nonzero(mask)[0]
            c = pos[f, col]
            cur = rot.normalize(pos[f, sh] - c)
            toward = rot.normalize(wrist[f] - c)
            goal = toward if kind == "far" else -toward
            r = np.linalg.norm(body.offsets[sh])
            full = rot.rotation_between(cur, goal)
            ang_full = rot.geodesic_angle(np.eye(3)[None], full)
            axis = rot.normalize(rot.matrix_to_axis_angle(full))
            lo, hi = np.zeros(len(f)), np.minimum(ang_full, max_swing)
            # smallest swing bringing the wrist into range (bisection), capped
            for _ in range(30):
                mid = 0.5 * (lo + hi)
                Rm = rot.axis_angle_rotation(axis, mid)
                s_new = c + r * np.einsum("nij,nj->ni", Rm, cur)
                dn = np.linalg.norm(wrist[f] - s_new, axis=-1)
                ok = dn <= reach if kind == "far" else dn >= d_min
                hi = np.where(ok, mid, hi)
                lo = np.where(ok, lo, mid)
            Rm = rot.axis_angle_rotation(axis, hi)
            new_world = Rm @ world[f, col]
            local[f, col] = np.swapaxes(world[f, PARENTS[col]], -1, -2) @ new_world
            world[f, col] = new_world
            pos[f, sh] = c + np.einsum("nij,j->ni", new_world, body.offsets[sh])
    return local


def check_targets(targets: TrackerTargets):
    """Raise ``ValueError`` unless ``targets`` has the required devices, frames and no NaN."""
    for d in REQUIRED_DEVICES:
        if d not in targets.pos:
            raise ValueError(f"a '{d}' tracker is required; the recording has {list(targets.pos)}")
    if targets.num_frames < 1:
        raise ValueError("the recording has no frames to solve")
    for d in targets.pos:
        for name, a in (("position", targets.pos[d]), ("orientation", targets.rot[d])):
            if not np.isfinite(a).all():
                bad = np.unique(np.nonzero(~np.isfinite(a))[0])
                raise ValueError(f"{d} {name} has NaN at frames {bad[:10].tolist()}: bridge gaps first")


def predict(targets: TrackerTargets, body: Body, runner=None, progress=None, stride=None,
            mirror=None, overlap=None) -> NetworkOutput:
    """The network stage of :func:`solve`: checked targets → :class:`NetworkOutput`.

    runner: what :func:`.model_choice.plan_models` takes: ``None`` (default: the shipped model
    for the recording's trackers, per stretch when a tracker is lost for long), a shipped
    model's name, an ``.onnx`` path, a MANIKIN :class:`~.model_runner.ModelRunner`, or a
    :class:`.model_choice.ModelPlan`.  The output's ``notes`` say which model solved what.
    stride, mirror, overlap: see :func:`run_network`."""
    from . import model_choice
    check_targets(targets)
    plan = runner if isinstance(runner, model_choice.ModelPlan) else model_choice.plan_models(targets, runner)
    for r in plan.runners:
        if r.contract.kind != "manikin":
            raise ValueError(f"{r.path}: solve() needs a MANIKIN model, got kind {shown(r.contract.kind)}")
    n = len(plan.runners)
    outs = []
    for k, r in enumerate(plan.runners):
        def part(x, k=k):
            if progress is not None:
                progress((k + float(x)) / n)
        outs.append(run_network(targets, body, r, progress=part, stride=stride, mirror=mirror,
                                overlap=overlap))
    net = outs[0] if n == 1 else blend_outputs(outs, plan.weights)
    net.notes = list(plan.notes)
    return net


def plan_feet(targets: TrackerTargets, body: Body, net: NetworkOutput, lock_feet=True):
    """Ankle targets for the legs: the network's, or the foot trackers', planted and above the floor.

    Returns ``(ankle_pos (T, 2, 3) metres, ankle_rot (T, 2, 3, 3) world, contacts (T, 2) bool)``.
    Works on the whole take at once (a plant can last the whole take); its arrays are small."""
    from .model_choice import tracker_weights
    ankle_pos, ankle_rot = net.ankle_pos.copy(), net.ankle_rot.copy()
    weights = tracker_weights(targets)
    u = np.stack([weights.get(d, np.zeros(targets.num_frames)) for d in ("left_foot", "right_foot")], 1)
    contact = net.contact.copy()
    contacts = contact > CONTACT_THRESHOLD
    if lock_feet and (u < 1.0).any():
        locked = lock_planted_feet(ankle_pos, contact, axes=LOCK_AXES, fps=targets.fps)
        # ease the blends in and out of each plant (no jerk); planted frames stay exactly put
        planted = contacts[..., None]
        locked = np.where(planted, locked, smooth_frames(locked, LOCK_SMOOTH_S * targets.fps))
        # a foot is reported planted on the frames it is actually held still (not while it
        # eases from one plant to the next, see lock_planted_feet's max_drift)
        step = np.linalg.norm(np.diff(locked[..., :2], axis=0), axis=-1)         # (T-1, 2)
        still_next = np.concatenate([step < 1e-9, np.ones((1, 2), bool)], 0)
        ankle_pos = locked
        contacts &= still_next | (u >= 1.0)
        if SETTLE_MAX > 0:
            ankle_pos = settle_planted_feet(ankle_pos, ankle_rot, contacts, body, targets.fps)
    # a foot tracker drives its ankle where it is tracked (weight 1), the network's foot where it
    # was lost for long (weight 0), cross-faded between
    for k, d in enumerate(("left_foot", "right_foot")):
        if (u[:, k] > 0).any():
            ankle_pos[:, k] = u[:, k, None] * targets.pos[d] + (1 - u[:, k, None]) * ankle_pos[:, k]
            ankle_rot[:, k] = blend_rotations(ankle_rot[:, k], targets.rot[d], u[:, k])
    # feet the network placed are kept above the floor; a tracked foot is where its tracker says
    lifted = keep_feet_above_floor(ankle_pos, ankle_rot, body)
    return np.where((u >= 1.0)[..., None], ankle_pos, lifted), ankle_rot, contacts


def _pose_torso(targets: TrackerTargets, net: NetworkOutput, body: Body, pelvis_w, f):
    """Torso FK of frames ``f`` (a slice), head on its tracker: ``(local, root_pos, pos, world)``
    as :func:`_torso_fk`.  ``pelvis_w``: the pelvis tracker's weight ``(T,)`` or None."""
    tp, tr = targets.pos, targets.rot
    if pelvis_w is not None and (pelvis_w[f] > 0).any():
        # six-tracker setting: the pelvis tracker wins where it is tracked (weight 1); the
        # head-anchored torso where it was lost for long, cross-faded between; the spine
        # bends so the head still reaches its tracker
        uf = pelvis_w[f]
        root_rot = blend_rotations(net.root_rot[f], tr["pelvis"][f], uf)
        loc, root, pos, world = _torso_fk(root_rot, net.torso_rot[f], tr["head"][f], tp["head"][f], body)
        root = root + uf[:, None] * (tp["pelvis"][f] - root)
        loc, pos, world = _bend_spine_to_head(loc, root, tp["head"][f], tr["head"][f], body, uf)
        return loc, root, pos, world
    return _torso_fk(net.root_rot[f], net.torso_rot[f], tr["head"][f], tp["head"][f], body)


def soften_leg_reach(hips, ankles, leg_length, sigma):
    """Ankle targets whose distance from the hip is low-passed (Gaussian, ``sigma`` frames).

    hips, ankles ``(T, 2, 3)`` metres (left, right); leg_length ``(2,)`` thigh + shank, metres.
    Where a predicted ankle hovers around the leg's full reach, the two-bone solve straightens
    and re-bends the knee within a frame or two (a pop: on the Bandai held-out takes 61 % of the
    leg frames were at full reach, and the knees' jerk was 1.3-1.8x the ground truth's).  Filtering
    the hip-ankle distance, clamped to the reach, turns those pops into a smooth stretch; the
    direction from the hip is kept.  ``sigma`` 0: the ankles, unchanged.  Returns a new array.
    """
    ankles = np.asarray(ankles, np.float64)
    if sigma <= 0:
        return ankles.copy()
    v = ankles - hips
    d = np.linalg.norm(v, axis=-1)
    reach = smooth_frames(np.minimum(d, np.asarray(leg_length, np.float64)[None]), sigma)
    return hips + v * (reach / np.maximum(d, 1e-9))[..., None]


def assemble(targets: TrackerTargets, body: Body, net: NetworkOutput, progress=None, lock_feet=True,
             chunk_frames=None) -> PoseResult:
    """The analytic stages of :func:`solve`: torso FK, feet, collars and limbs from ``net``.

    Runs without the network, so a body with other limb lengths (see
    :func:`.calibration.adapt_arms_to_reach`) re-solves in a fraction of the time.
    chunk_frames: frames posed at a time (default :data:`ASSEMBLY_CHUNK_FRAMES`); each frame
    is posed on its own (the leg-reach filter looks past the chunk's edges), so the result does
    not depend on it, only the peak memory does.
    """
    from .model_choice import tracker_weights
    check_targets(targets)
    T = targets.num_frames
    t_start = time.perf_counter()
    ankle_pos, ankle_rot, contacts = plan_feet(targets, body, net, lock_feet=lock_feet)
    weights = tracker_weights(targets)
    zeros = np.zeros(T)
    # a foot with no tracker (or a lost one) has no target to miss: the straight leg points at the
    # prediction, and "out of reach" notes are for trackers the body cannot reach
    foot_exact = np.stack([weights.get(d, zeros) >= 1.0 for d in ("left_foot", "right_foot")], 1)
    pelvis_w = weights.get("pelvis")
    lengths = body.limb_lengths()
    step = max(int(chunk_frames or ASSEMBLY_CHUNK_FRAMES), 1)
    local = np.empty((T, NUM_JOINTS, 3, 3))
    root_pos = np.empty((T, 3))
    swivel = np.empty((T, 4))
    reach_error = np.empty((T, 4))
    # the leg-reach filter's radius: the torso is posed that many frames beyond each chunk, so the
    # filter sees what it would on the whole take and the result does not depend on the chunking
    sigma = LEG_REACH_SMOOTH_S * targets.fps
    margin = int(np.ceil(3 * sigma)) if sigma > 0 else 0
    for a in range(0, T, step):
        f = slice(a, min(a + step, T))
        g = slice(max(a - margin, 0), min(f.stop + margin, T))
        loc, root, pos, world = _pose_torso(targets, net, body, pelvis_w, g)
        legs = soften_leg_reach(pos[:, ls.LIMB_BASE[2:]], ankle_pos[g], lengths[2:].sum(-1), sigma)
        inner = slice(a - g.start, f.stop - g.start)
        loc, root, pos, world, legs = loc[inner], root[inner], pos[inner], world[inner], legs[inner]
        # a tracked foot is where its tracker says; a predicted one reaches its softened target,
        # kept out of the floor (the filter may stretch a leg a few millimetres down)
        legs = np.where(foot_exact[f][..., None], ankle_pos[f], keep_feet_above_floor(legs, ankle_rot[f], body))
        tp, tr = ({d: v[f] for d, v in targets.pos.items()}, {d: v[f] for d, v in targets.rot.items()})
        loc = _reach_collars(loc, pos, world, np.stack([tp["left_hand"], tp["right_hand"]], 0), body)
        # limbs (bases and their parents from the torso FK above)
        ends = np.concatenate([np.stack([tp["left_hand"], tp["right_hand"]], 1), legs], 1)
        end_rot = np.stack([tr["left_hand"], tr["right_hand"], ankle_rot[f, 0], ankle_rot[f, 1]], 1)
        sol, swivel[f] = ls.solve_limbs_within_limits(pos[:, ls.LIMB_BASE], ends, net.swivel[f], lengths,
                                                      world[:, ls.LIMB_PARENT], end_rot=end_rot)
        loc[:, ls.LIMB_BASE] = sol.base_local
        loc[:, ls.LIMB_MID] = sol.mid_local
        loc[:, ls.LIMB_END] = sol.end_local
        local[f], root_pos[f], reach_error[f] = loc, root, sol.reach_error
        reach_error[f, 2:] = np.where(foot_exact[f], reach_error[f, 2:], 0.0)
        del loc, pos, world, sol
        if progress is not None:
            progress(f.stop / T)
    at_limit = np.abs(np.angle(np.exp(1j * (swivel - net.swivel)))) > 1e-9
    return PoseResult(fps=float(targets.fps), body=body, local_rot=local, root_pos=root_pos,
                      swivel=swivel, contacts=contacts, reach_error=reach_error, targets=targets,
                      at_limit=at_limit,
                      timings={"solver": time.perf_counter() - t_start}, notes=list(net.notes or []))


def solve(targets: TrackerTargets, body: Body, runner=None, progress=None, lock_feet=True,
          fk_runner=None, lower_body="ik", stride=None, chunk_frames=None, mirror=None, overlap=None):
    """Full-body pose for every frame of ``targets``: :func:`predict`, then :func:`assemble`.

    runner: see :func:`predict` (default: the shipped model for the recording's trackers; the
    result's ``notes`` say which).  progress: optional ``callable(fraction)``; raise :class:`SolveCancelled`
    (or anything) from it to stop.  lower_body: ``"ik"`` (MANIKIN) or
    ``"fk"`` (ablation: legs from ``fk_runner``'s predicted rotations).
    stride, mirror, overlap: see :func:`run_network` (``overlap=3``: each frame seen by three
    windows, 1.2 % more accurate on HDM05 at 1.5 times the network time; :data:`OVERLAP_CHOICES`).
    chunk_frames: see :func:`assemble`.  The result's ``with_body(body)`` re-assembles the same
    network output with another body (MANIKIN only; None for the ablation).
    """
    def report(x):
        if progress is not None:
            progress(x)

    t_start = time.perf_counter()
    net = predict(targets, body, runner, progress=lambda x: report(0.6 * x), stride=stride, mirror=mirror,
                  overlap=overlap)
    t_net = time.perf_counter()
    result = assemble(targets, body, net, progress=lambda x: report(0.6 + 0.35 * x), lock_feet=lock_feet,
                      chunk_frames=chunk_frames)
    if lower_body == "fk":
        if fk_runner is None:
            raise ValueError("lower_body='fk' needs fk_runner (the network-only model)")
        fk_net = run_network(targets, body, fk_runner, mirror=mirror)
        legs = [J[n] for n in ("left_hip", "right_hip", "left_knee", "right_knee",
                               "left_ankle", "right_ankle")]
        result.local_rot[:, legs] = fk_net.local_rot[:, [j - 1 for j in legs]]
    else:
        def with_body(new_body, progress=None):
            return assemble(targets, new_body, net, progress=progress, lock_feet=lock_feet,
                            chunk_frames=chunk_frames)
        result.with_body = with_body
    result.timings = {"network": t_net - t_start, "solver": time.perf_counter() - t_net}
    report(1.0)
    return result
