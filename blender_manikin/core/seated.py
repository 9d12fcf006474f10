"""Seated performers: legs on a chair, feet on the floor.

Never imports bpy.

The pose network was trained on people standing, walking, crouching and lying; a performer
sitting at a desk or in a cockpit gives it a head at about two thirds of their standing height
and it answers with the nearest thing it knows, a deep crouch.  With the *Seated* posture
(:class:`.solve.SolveSettings` ``posture="seated"``) the torso and arms are solved as always and
:func:`seat_legs` then sits the legs down: each thigh runs forward from its hip (along the
pelvis's heading, :data:`KNEE_SPREAD_DEG` out) to a knee whose shin stands upright on a foot flat
on the floor, so the knee is as high above the floor as the shank is long over the standing
ankle.  The hips stay where the torso put them: a lower seat bends the knees more, a higher
one less (a hip more than a thigh above the knee's height hangs the thigh straight down).  Both
feet are planted: held where they stand while the pelvis keeps its heading (:func:`hold_seated_feet`:
the hips sway as the performer leans and looks round, the feet do not), moved on when the chair
turns.  The legs are solved by the same analytic limb solver (their swivel from the
knee placed so), so the swivel sliders still turn the knees afterwards.

A seated take's head says little about the performer's standing height, so the stature is the
typed one, or, without it, the seated head height divided by :data:`SEATED_HEAD_HEIGHT` (a chair
seat at knee height: the head joint about 0.65 of stature above the floor; a chair 5 cm lower or
higher moves that estimate by about 3 %), which the summary says.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from . import limb_solver as ls
from .features import heading_yaw, rot_z
from .skeleton import J

#: the head joint's height above the floor of a performer seated on a chair at knee height, in
#: statures: seat 0.257 (a 45 cm seat for 1.75 m) + hip joint above the seat 0.05 + head above
#: the hips 0.34 (:data:`.skeleton.PROPORTIONS`: head 0.870, hips 0.530)
SEATED_HEAD_HEIGHT = 0.647
#: each thigh turned this far out from the pelvis's forward direction (degrees)
KNEE_SPREAD_DEG = 8.0
#: the postures a solve knows
POSTURES = ("standing", "seated")

_LEGS = (2, 3)                                      # limb indices of the legs (skeleton.LIMBS)


def seated_leg_targets(hips, pelvis_rot, body, floor=0.0):
    """Knee and ankle positions and ankle orientations of seated legs.

    hips: ``(T, 2, 3)`` hip joint positions (left, right), metres, Blender axes; pelvis_rot:
    ``(T, 3, 3)`` the pelvis's world rotation (its heading is the legs' forward); body: the
    :class:`.skeleton.Body`.  Returns ``(knees (T, 2, 3), ankles (T, 2, 3), ankle_rot (T, 2, 3,
    3))``: each shin upright on a flat foot on the floor ``floor``, the knee as high as that
    allows, the thigh forward from the hip (see the module docstring)."""
    hips = np.asarray(hips, np.float64)
    yaw = heading_yaw(np.asarray(pelvis_rot, np.float64))
    rest = body.rest_positions()
    lengths = body.limb_lengths()
    knees = np.empty_like(hips)
    ankles = np.empty_like(hips)
    for k, side in enumerate((1.0, -1.0)):          # left legs turn out to +X of the body, right to -X
        thigh, shank = lengths[_LEGS[k]]
        ankle_z = floor + rest[J["left_ankle" if side > 0 else "right_ankle"], 2]     # standing, on its soles
        out = np.radians(KNEE_SPREAD_DEG) * side
        heading = rot_z(yaw + out)                  # (T, 3, 3): the thigh's forward, turned out
        fwd = heading @ np.array([0.0, -1.0, 0.0])
        knee_z = ankle_z + shank
        dz = np.clip(knee_z - hips[:, k, 2], -thigh, thigh)
        run = np.sqrt(np.maximum(thigh ** 2 - dz ** 2, 0.0))
        knees[:, k] = hips[:, k] + fwd * run[:, None]
        knees[:, k, 2] += dz
        ankles[:, k] = knees[:, k] - np.array([0.0, 0.0, shank])
    ankle_rot = np.repeat(rot_z(yaw)[:, None], 2, axis=1)           # feet flat, pointing ahead
    return knees, ankles, ankle_rot


#: degrees per second the pelvis may turn while the seated feet stay planted; a turn of the chair
#: (faster) lets them go round with it
SEATED_TURN_RATE = 30.0
#: metres a seated foot is held away from where the seat puts it before it is set down anew
#: (:func:`.pipeline.lock_planted_feet`'s ``max_drift``): the hips sway with the torso as the
#: performer leans and turns the head, the feet do not
SEATED_FOOT_DRIFT = 0.15


def hold_seated_feet(ankles, pelvis_rot, fps):
    """Seated ankles ``(T, L, 3)`` (metres) held where they stand, on the floor plane (x, y), while
    the pelvis's heading ``pelvis_rot`` ``(T, 3, 3)`` turns slower than :data:`SEATED_TURN_RATE`
    (the feet are planted: the seat puts them under knees that sway with the hips); a swivel
    chair's turn, or a drift past :data:`SEATED_FOOT_DRIFT`, moves them on, eased
    (:func:`.pipeline.lock_planted_feet`).  Returns a new array."""
    from .pipeline import lock_planted_feet
    ankles = np.asarray(ankles, np.float64)
    T = ankles.shape[0]
    if T < 2:
        return ankles.copy()
    yaw = np.unwrap(heading_yaw(np.asarray(pelvis_rot, np.float64)))
    rate = np.degrees(np.abs(np.gradient(yaw))) * float(fps)
    still = np.repeat((rate < SEATED_TURN_RATE)[:, None], ankles.shape[1], axis=1).astype(np.float64)
    return lock_planted_feet(ankles, still, threshold=0.5, axes=(0, 1), max_drift=SEATED_FOOT_DRIFT, fps=fps)


def seat_legs(result, floor=0.0, legs=(0, 1)):
    """A :class:`.pose_result.PoseResult` with its legs seated (see the module docstring): the
    torso, arms and root as in ``result``, the legs ``legs`` (0 left, 1 right; a leg whose foot
    has a tracker stays on it) solved onto :func:`seated_leg_targets`, their feet planted.
    Returns a new result; ``result`` is not changed."""
    legs = tuple(int(k) for k in legs)
    if not legs:
        return result
    body = result.body
    ids = np.array([_LEGS[k] for k in legs])
    base = ls.LIMB_BASE[ids]
    # the hips and the pelvis (the legs' parent) only, a chunk at a time: a long take's whole FK
    # would stay cached on the result
    T = result.num_frames
    all_hips, pelvis = np.empty((T, 2, 3)), np.empty((T, 3, 3))
    for f, p, w in result.fk_chunks():
        all_hips[f], pelvis[f] = p[:, ls.LIMB_BASE[list(_LEGS)]], w[:, J["pelvis"]]
    hips = all_hips[:, list(legs)]
    parent = np.repeat(pelvis[:, None], len(legs), axis=1)
    knees, ankles, ankle_rot = (a[:, list(legs)] for a in seated_leg_targets(all_hips, pelvis, body, floor))
    ankles = hold_seated_feet(ankles, pelvis, result.fps)
    swivel_legs = ls.swivel_from_positions(hips, knees, ankles, parent, limb_ids=ids)
    sol = ls.solve_limbs(hips, ankles, swivel_legs, body.limb_lengths()[ids], parent, end_rot=ankle_rot,
                         limb_ids=ids)
    local = result.local_rot.copy()
    local[:, base] = sol.base_local
    local[:, ls.LIMB_MID[ids]] = sol.mid_local
    local[:, ls.LIMB_END[ids]] = sol.end_local
    swivel = result.swivel.copy()
    swivel[:, ids] = swivel_legs
    reach = None if result.reach_error is None else result.reach_error.copy()
    if reach is not None:
        reach[:, ids] = 0.0
    at_limit = None if result.at_limit is None else result.at_limit.copy()
    if at_limit is not None:
        at_limit[:, ids] = False
    contacts = np.ones((result.num_frames, 2), bool) if result.contacts is None else result.contacts.copy()
    contacts[:, list(legs)] = True
    return dataclasses.replace(result, local_rot=local, swivel=swivel, reach_error=reach, at_limit=at_limit,
                               contacts=contacts, with_body=None, _fk=None)


#: a take whose head stands near its standing height (the 90th percentile) for a tenth of it and
#: sits (more than half the standing-to-seated drop below that, within a quarter of the drop of
#: the seated height) for another tenth was partly made standing (:func:`stood_and_sat`)
STOOD_FRACTION = 0.10


def stood_and_sat(head_z, drop):
    """``(stood, seated_head)``: whether head heights ``head_z`` (metres) show a performer who
    stood for a part of the take and sat for another (:data:`STOOD_FRACTION` of it each), the
    seated head ``drop`` metres below the standing one; and the median head height of the frames
    it sat (all frames' when it did not stand).  A take that stands and sits: its median head
    may be a standing one, which is no seated head height."""
    z = np.asarray(head_z, np.float64)
    z = z[np.isfinite(z)]
    if not z.size:
        return False, float("nan")
    hi = float(np.percentile(z, 90))
    low = z < hi - 0.5 * float(drop)
    if (STOOD_FRACTION <= low.mean() <= 1.0 - STOOD_FRACTION
            and abs(float(np.median(z[low])) - (hi - float(drop))) < 0.25 * float(drop)):
        return True, float(np.median(z[low]))
    return False, float(np.median(z))


def stature_from_seated_head(head_height):
    """Stature (metres) of a performer whose head joint stands ``head_height`` metres above the
    floor while seated (:data:`SEATED_HEAD_HEIGHT`)."""
    return float(head_height) / SEATED_HEAD_HEIGHT
