"""Which pose network solves a recording: one per tracker set, chosen by the recording's devices.

The add-on ships one network per tracker set (:data:`SHIPPED_MODELS`), each listing its input
devices in its ONNX contract:

* ``head_hands``: head and both hands (``manikin_s.onnx``);
* ``pelvis``: head, hands and a pelvis (waist) tracker (``manikin_s_pelvis.onnx``);
* ``six``: head, hands, pelvis and both feet (``manikin_s_six.onnx``).

``auto`` picks, frame by frame, the largest shipped set whose devices the recording tracks
there.  A tracker lost for up to :data:`TRACKER_BRIDGE_S` seconds is bridged like any gap (the
resampled poses are interpolated across it); lost for longer, that stretch is solved with the
next smaller set, cross-faded over :data:`MODEL_BLEND_S` seconds that end where the tracker is
lost (and start where it is back), so no frame uses a bridged pose of a lost tracker at full
weight.  :func:`tracker_weights` gives the same ramps for the analytic stages (a pelvis or foot
tracker drives the pelvis or ankle where its weight is 1).

A model named by the user (``--model``, the panel) solves the whole take.  No bpy.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from .devices import DEVICES, EXTRA_DEVICES, LABELS, REQUIRED_DEVICES
from .model_runner import MODELS_DIR, ModelError, load_model
from .runs import runs

#: name → (file in ``models/``, input devices), smallest set first; the sets are nested
SHIPPED_MODELS = {
    "head_hands": ("manikin_s.onnx", REQUIRED_DEVICES),
    "pelvis": ("manikin_s_pelvis.onnx", REQUIRED_DEVICES + ("pelvis",)),
    "six": ("manikin_s_six.onnx", DEVICES),
}
#: what the user interface calls each shipped model
MODEL_LABELS = {"head_hands": "head and hands", "pelvis": "head, hands and pelvis",
                "six": "head, hands, pelvis and feet"}
#: seconds a tracker may be lost and still be bridged (longer: the smaller model there)
TRACKER_BRIDGE_S = 3.0
#: seconds over which a stretch's model (and a lost tracker's weight) is cross-faded
MODEL_BLEND_S = 0.5


@dataclass
class ModelPlan:
    """The networks of one solve and their per-frame weights.

    runners: the :class:`~.model_runner.ModelRunner` of each model used; weights: ``(T,)``
    float per runner, summing to 1 on every frame; names: each model's name (a shipped name or
    the file's stem); notes: plain-language lines for the solve summary."""
    runners: list
    weights: list
    names: list
    notes: list = field(default_factory=list)


def shipped_model_path(name):
    """The file of the shipped model ``name`` (it may not be installed)."""
    return os.path.join(MODELS_DIR, SHIPPED_MODELS[name][0])


def installed_models():
    """``[(name, path, devices), ...]`` of the shipped models present, smallest set first.

    ``$BLENDER_MANIKIN_MODEL`` (a model you trained) stands in for the shipped model whose
    devices its contract lists."""
    custom_devices = None
    custom = os.environ.get("BLENDER_MANIKIN_MODEL")
    if custom:
        custom_devices = tuple(load_model(custom).contract.devices)
    out = []
    for name, (fname, devices) in SHIPPED_MODELS.items():
        path = custom if custom_devices == tuple(devices) else os.path.join(MODELS_DIR, fname)
        if os.path.isfile(path):
            out.append((name, path, devices))
    return out


def resolve_model(spec):
    """``None`` for automatic choice (``spec`` None, ``""`` or ``"auto"``), else a model path:
    a shipped model's name (``head_hands``, ``pelvis``, ``six``, or its file's stem) or an
    ``.onnx`` file.  Raises ``ValueError`` naming what is known when ``spec`` is neither."""
    if spec is None or str(spec).strip().lower() in ("", "auto"):
        return None
    s = str(spec).strip()
    for name, (fname, _) in SHIPPED_MODELS.items():
        if s.lower() in (name, os.path.splitext(fname)[0]):
            path = os.path.join(MODELS_DIR, fname)
            if not os.path.isfile(path):
                raise ValueError(f"the {name} model ({fname}) is not installed in {MODELS_DIR}")
            return path
    path = os.path.expanduser(s)
    if os.path.isfile(path):
        return path
    raise ValueError(f"model {s!r}: not a file, nor one of auto, {', '.join(SHIPPED_MODELS)}")


def tracked_frames(targets, device, bridge_s=TRACKER_BRIDGE_S):
    """``(T,)`` bool: frames where ``device`` is tracked, its gaps of at most ``bridge_s``
    seconds included (they are bridged; at either end of the take the nearest pose is held).
    All False when the recording lacks the device."""
    T = targets.num_frames
    if device not in targets.pos:
        return np.zeros(T, bool)
    valid = np.asarray(targets.valid.get(device, np.ones(T, bool)), bool)
    if valid.shape != (T,):
        valid = np.ones(T, bool)
    out = valid.copy()
    limit = bridge_s * float(targets.fps)
    for a, b in runs(~valid):
        if (b - a) <= limit and (a > 0 or b < T):
            out[a:b] = True
    return out


def _ramp(mask, fps, blend_s=MODEL_BLEND_S):
    """``(T,)`` float in [0, 1]: 1 on ``mask``'s frames, easing linearly to 0 over ``blend_s``
    seconds *inside* each run (it is 0 from the first frame outside the run on).  Runs shorter
    than the ramp peak below 1.  Monotone: a subset mask never gets a larger weight."""
    mask = np.asarray(mask, bool)
    T = mask.shape[0]
    n = max(int(round(blend_s * fps)), 1)
    if mask.all() or not mask.any():
        return mask.astype(np.float64)
    # distance (frames) to the nearest frame outside the mask; the take's ends do not count
    idx = np.arange(T)
    outside = np.nonzero(~mask)[0]
    pos = np.searchsorted(outside, idx)
    left = np.where(pos > 0, idx - outside[np.clip(pos - 1, 0, len(outside) - 1)], T + n)
    right = np.where(pos < len(outside), outside[np.clip(pos, 0, len(outside) - 1)] - idx, T + n)
    dist = np.minimum(left, right)
    return np.where(mask, np.clip(dist / n, 0.0, 1.0), 0.0)


def tracker_weights(targets, bridge_s=TRACKER_BRIDGE_S, blend_s=MODEL_BLEND_S):
    """device → ``(T,)`` weight in [0, 1] of each extra tracker (pelvis, feet) in the recording:
    1 where it is tracked (gaps up to ``bridge_s`` bridged), easing to 0 over ``blend_s``
    before a longer loss and back after it."""
    return {d: _ramp(tracked_frames(targets, d, bridge_s), targets.fps, blend_s)
            for d in EXTRA_DEVICES if d in targets.pos}


def _device_words(devices):
    return ", ".join(LABELS[d].lower() for d in devices)


def _span(a, b, fps):
    return f"{a / fps:.1f}-{b / fps:.1f} s"


def plan_models(targets, model=None, threads=None, bridge_s=TRACKER_BRIDGE_S, blend_s=MODEL_BLEND_S):
    """The networks that solve ``targets`` (:class:`~.pose_result.TrackerTargets`).

    model: ``None`` / ``"auto"`` (the installed shipped models, chosen per frame by the tracked
    devices), a shipped name, an ``.onnx`` path, or a :class:`~.model_runner.ModelRunner`
    (which solves the whole take).  threads: onnxruntime threads per loaded model.
    Returns a :class:`ModelPlan`."""
    if model is not None and not isinstance(model, (str, bytes)) and not hasattr(model, "__fspath__"):
        runner = model      # a loaded runner
        return ModelPlan([runner], [np.ones(targets.num_frames)], [_stem(runner.path)],
                         [_whole_take_note(runner, targets)])
    path = resolve_model(model)
    if path is not None:
        runner = load_model(path, threads=threads)
        lacking = [d for d in runner.contract.devices if d not in targets.pos]
        if lacking:
            raise ModelError(f"model {_stem(path)} takes the {_device_words(lacking)} tracker(s), which the "
                             f"recording does not have (it has {_device_words(targets.pos)}): choose the model "
                             f"for its trackers (Pose Model: Automatic, --model auto)")
        return ModelPlan([runner], [np.ones(targets.num_frames)], [_stem(path)],
                         [_whole_take_note(runner, targets, chosen=True)])
    T = targets.num_frames
    fps = float(targets.fps)
    tracked = {d: tracked_frames(targets, d, bridge_s) for d in DEVICES}
    chain = [(name, path, devices) for name, path, devices in installed_models()]
    if not chain:
        raise ModelError(f"no pose model installed in {MODELS_DIR} (reinstall the add-on, or train one "
                         f"with 'python -m blender_manikin.training.train')")
    # the models whose devices the recording has at all, smallest first; each level's frames
    levels = [(name, path, devices) for name, path, devices in chain
              if all(d in targets.pos for d in devices)]
    if not levels:
        raise ModelError(f"no installed model takes the recording's devices ({_device_words(targets.pos)})")
    frames = [np.logical_and.reduce([tracked[d] for d in devices]) if devices else np.ones(T, bool)
              for _, _, devices in levels]
    frames[0] = np.ones(T, bool)               # the smallest set solves whatever is left
    for k in range(1, len(frames)):            # nested: a level needs every smaller one's devices
        frames[k] &= frames[k - 1]
    ramps = [np.ones(T)] + [_ramp(f, fps, blend_s) for f in frames[1:]]
    weights = [ramps[k] - (ramps[k + 1] if k + 1 < len(ramps) else 0.0) for k in range(len(ramps))]
    used = [k for k in range(len(levels)) if weights[k].max() > 1e-9]
    runners = [load_model(levels[k][1], threads=threads) for k in used]
    names = [levels[k][0] for k in used]
    top = used[-1]
    notes = [f"model {MODEL_LABELS.get(levels[top][0], levels[top][0])} ({os.path.basename(levels[top][1])})"]
    extra = [d for d in EXTRA_DEVICES if d in targets.pos]
    missing_model = [d for d in extra if not any(d in devs for _, _, devs in levels)]
    if missing_model:
        notes[0] += (f"; no installed model takes the {_device_words(missing_model)} tracker(s): they "
                     f"drive the solve directly")
    for k in used[:-1]:
        # the stretches this smaller model solves (with the lost trackers that pushed it there)
        lost = [d for d in levels[k + 1][2] if d not in levels[k][2] and not tracked[d].all()]
        stretches = runs(weights[k] > 0.999)
        if not stretches:
            continue
        spans = ", ".join(_span(a, b, fps) for a, b in stretches[:4]) + (" ..." if len(stretches) > 4 else "")
        why = f"{_device_words(lost)} tracker lost over {bridge_s:g} s" if lost else "trackers lost"
        notes.append(f"{why}: the {MODEL_LABELS.get(levels[k][0], levels[k][0])} model on {spans} "
                     f"(blended over {blend_s:g} s)")
    return ModelPlan(runners, [weights[k] for k in used], names, notes)


#: backbones the solve summary names beside a chosen model (the contract's ``architecture.arch``; the
#: shipped Transformer, ``posenet``, goes unnamed)
BACKBONE_LABELS = {"dap": "Dual Attention Poser"}


def _stem(path):
    return os.path.splitext(os.path.basename(str(path)))[0]


def _whole_take_note(runner, targets, chosen=False):
    devices = tuple(runner.contract.devices)
    arch = getattr(runner.contract, "arch", None)
    backbone = f"{BACKBONE_LABELS[arch]}; " if arch in BACKBONE_LABELS else ""
    if getattr(runner.contract, "causal", False):        # run_network: one window ending at each frame, no overlap
        backbone += "causal: each frame from a window ending at it; "
    note = f"model {_stem(runner.path)} ({backbone}{_device_words(devices)}{', chosen' if chosen else ''})"
    unused = [d for d in EXTRA_DEVICES if d in targets.pos and d not in devices]
    if unused:
        note += f"; the {_device_words(unused)} tracker(s) drive the solve directly, not the network"
    return note
