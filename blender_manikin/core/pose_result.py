"""Data passed between the solver and the Blender/JSON writers.  Never imports bpy."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .skeleton import Body, LIMB_NAMES, LIMBS, forward_kinematics

#: (end device in words, base joint, mid joint) of each limb, for messages
_LIMB_WORDS = {"left_arm": ("left hand", "shoulder", "elbow"), "right_arm": ("right hand", "shoulder", "elbow"),
               "left_leg": ("left foot", "hip", "knee"), "right_leg": ("right foot", "hip", "knee")}

from .devices import DEVICE_JOINT, DEVICES  # noqa: E402,F401  (the vocabulary lives in core/devices.py)

#: the device that drives each limb's end joint (wrist: hand, ankle: foot)
_END_DEVICE = {j: d for d, j in DEVICE_JOINT.items()}

#: frames the writers convert at a time (:meth:`PoseResult.fk_chunks`, the BVH writer): bounds
#: their memory on long takes; what they write does not depend on it
CHUNK_FRAMES = 8192


@dataclass
class TrackerTargets:
    """Per-frame joint targets derived from devices (after device offsets).

    pos: device -> ``(T, 3)`` float64 metres, Blender world axes (Z-up, floor z=0).
    rot: device -> ``(T, 3, 3)`` world orientation of the *joint* the device
    drives (head, wrist, pelvis, ankle), in the body-model convention
    (identity = T-pose rest orientation, body facing -Y).
    valid: device -> ``(T,)`` bool, False where the sample was bridged over a gap.
    """
    fps: float
    pos: dict
    rot: dict
    valid: dict = field(default_factory=dict)

    @property
    def num_frames(self) -> int:
        return int(next(iter(self.pos.values())).shape[0])

    @property
    def devices(self):
        return tuple(d for d in DEVICES if d in self.pos)

    def frames(self, sl: slice) -> "TrackerTargets":
        """The targets of the frames ``sl`` (a slice), as a new object (the arrays are views)."""
        return TrackerTargets(fps=self.fps, pos={d: v[sl] for d, v in self.pos.items()},
                              rot={d: v[sl] for d, v in self.rot.items()},
                              valid={d: v[sl] for d, v in self.valid.items()})


@dataclass
class PoseResult:
    """A solved full-body animation.

    local_rot: ``(T, 22, 3, 3)`` local joint rotations (body-model convention).
    root_pos: ``(T, 3)`` pelvis world position, metres, Blender axes.
    swivel: ``(T, 4)`` radians, limbs in ``LIMB_NAMES`` order.
    contacts: ``(T, 2)`` bool, left/right foot planted.
    reach_error: ``(T, 4)`` metres the limb end missed its target (0 = exact).
    at_limit: ``(T, 4)`` bool, frames where the swivel was moved to the
    shoulder's / hip's axial rotation limit (the prediction was implausible).
    Frame k is at time ``t0 + k / fps`` seconds of the recording clock.
    """
    fps: float
    body: Body
    local_rot: np.ndarray
    root_pos: np.ndarray
    swivel: np.ndarray
    contacts: np.ndarray | None = None
    reach_error: np.ndarray | None = None
    at_limit: np.ndarray | None = None
    targets: TrackerTargets | None = None
    t0: float = 0.0
    timings: dict = field(default_factory=dict)      # seconds per stage, e.g. network / solver
    notes: list = field(default_factory=list)        # which model(s) solved the take (the summary)
    #: ``(body, progress=None) -> PoseResult``: the same network output assembled with another
    #: body (:func:`.pipeline.solve` sets it; None where a re-solve must run the solver again)
    with_body: object = field(default=None, repr=False, compare=False)
    _fk: tuple | None = field(default=None, repr=False)

    @property
    def num_frames(self) -> int:
        return int(self.local_rot.shape[0])

    def frames(self, sl: slice) -> "PoseResult":
        """The frames ``sl`` (a slice with step 1) of this result, as a new result whose ``t0`` is
        its first frame's time (the arrays are views; ``with_body`` is not carried over)."""
        start = range(self.num_frames)[sl].start if self.num_frames else 0

        def cut(a):
            return None if a is None else a[sl]
        return PoseResult(fps=self.fps, body=self.body, local_rot=self.local_rot[sl], root_pos=self.root_pos[sl],
                          swivel=self.swivel[sl], contacts=cut(self.contacts), reach_error=cut(self.reach_error),
                          at_limit=cut(self.at_limit),
                          targets=None if self.targets is None else self.targets.frames(sl),
                          t0=self.t0 + start / self.fps, timings=dict(self.timings), notes=list(self.notes))

    def scaled(self, factor) -> "PoseResult":
        """This result with every length times ``factor`` (the body, the root path, the reach
        errors and the tracker targets' positions; rotations, swivels and contacts as they are):
        e.g. metres into a Blender scene's units.  ``with_body`` is not carried over."""
        k = float(factor)
        targets = None
        if self.targets is not None:
            t = self.targets
            targets = TrackerTargets(fps=t.fps, pos={d: np.asarray(v) * k for d, v in t.pos.items()},
                                     rot=dict(t.rot), valid=dict(t.valid))
        return PoseResult(fps=self.fps, body=self.body.scaled(k), local_rot=self.local_rot,
                          root_pos=np.asarray(self.root_pos) * k, swivel=self.swivel, contacts=self.contacts,
                          reach_error=None if self.reach_error is None else np.asarray(self.reach_error) * k,
                          at_limit=self.at_limit, targets=targets, t0=self.t0, timings=dict(self.timings),
                          notes=list(self.notes))

    def fk(self):
        """``(positions (T,22,3), world_rot (T,22,3,3))``, cached."""
        if self._fk is None:
            self._fk = forward_kinematics(self.local_rot, self.root_pos, self.body)
        return self._fk

    def fk_chunks(self, chunk=None):
        """``(frames slice, positions (n, 22, 3), world_rot (n, 22, 3, 3))`` for successive chunks
        of :data:`CHUNK_FRAMES` frames (or ``chunk``): the numbers of :meth:`fk` (FK is per frame),
        without building the whole take's arrays unless :meth:`fk` already did."""
        T = self.num_frames
        step = max(int(chunk or CHUNK_FRAMES), 1)
        for a in range(0, T, step):
            f = slice(a, min(a + step, T))
            if self._fk is not None:
                yield f, self._fk[0][f], self._fk[1][f]
            else:
                yield (f,) + tuple(forward_kinematics(self.local_rot[f], self.root_pos[f], self.body))

    @property
    def positions(self):
        return self.fk()[0]

    @property
    def world_rot(self):
        return self.fk()[1]

    def swivel_dict(self):
        return {name: self.swivel[:, i] for i, name in enumerate(LIMB_NAMES)}

    def misses(self, limb, tolerance=0.005):
        """Frames on which limb ``limb`` (index into :data:`.skeleton.LIMBS`) missed its target by
        more than ``tolerance`` metres, split by why: ``(far, close)``, two ``(T,)`` bool arrays.
        *far*: the target is further from the shoulder / hip than the solved hand / ankle (out of
        reach); *close*: nearer than it (inside the most-flexed elbow / knee).  Without targets for
        the limb every miss counts as far.  All False when there is no ``reach_error``.
        """
        T = self.local_rot.shape[0]
        if self.reach_error is None:
            return np.zeros(T, bool), np.zeros(T, bool)
        name, base_j, _, end_j = LIMBS[limb]
        bad = self.reach_error[:, limb] > tolerance
        far = bad.copy()
        dev = _END_DEVICE[end_j]
        if bad.any() and self.targets is not None and dev in self.targets.pos:
            f = np.nonzero(bad)[0]          # FK on the frames that missed only (long takes)
            pos = self.fk()[0][f] if self._fk is not None else \
                forward_kinematics(self.local_rot[f], self.root_pos[f], self.body)[0]
            far[f] = (np.linalg.norm(self.targets.pos[dev][f] - pos[:, base_j], axis=-1)
                      > np.linalg.norm(pos[:, end_j] - pos[:, base_j], axis=-1))
        return far, bad & ~far

    def quality_notes(self, reach_tolerance=0.005):
        """Plain-language notes on where the solve had to give way, for the user.

        One string per limb that missed its target by more than
        ``reach_tolerance`` metres on some frames: further than the arm or leg
        reaches (check the body size) or closer to the shoulder / hip than the
        elbow / knee folds (check the device offsets); and one per limb whose
        predicted swivel was moved to a joint limit.  ``[]`` when the
        solve is clean.
        """
        notes = []
        if self.reach_error is not None:
            for i, name in enumerate(LIMB_NAMES):
                far, close = self.misses(i, reach_tolerance)
                end, base, mid = _LIMB_WORDS[name]
                if far.any():
                    notes.append(f"{end} out of reach on {int(far.sum())} frame(s), by up to "
                                 f"{100 * float(self.reach_error[far, i].max()):.1f} cm (check the body size)")
                if close.any():
                    notes.append(f"{end} closer to the {base} than the {mid} can fold on {int(close.sum())} "
                                 f"frame(s), by up to {100 * float(self.reach_error[close, i].max()):.1f} cm "
                                 f"(check the device offsets)")
        if self.at_limit is not None:
            for i, name in enumerate(LIMB_NAMES):
                n = int(np.count_nonzero(self.at_limit[:, i]))
                if n:
                    joint = _LIMB_WORDS[name][1]
                    notes.append(f"{name.replace('_', ' ')} swivel held at the {joint}'s rotation limit "
                                 f"on {n} frame(s)")
        return notes
