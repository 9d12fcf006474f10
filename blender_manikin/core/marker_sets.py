"""Anatomical marker sets → the joint centres a keypoint layout names.  No bpy.

Optical motion capture and OpenCap put markers on the skin over bony landmarks, not at the joint
centres the solver wants.  Two marker sets are recognised by their names (case-insensitive; a
Vicon ``Subject:`` prefix and OpenCap's ``_study`` suffix are dropped, ``.`` reads as ``_``):

* **OpenCap** (the marker augmenter's output, in every OpenCap ``.trc``): ``r.ASIS_study``,
  ``L.ASIS_study``, ``r.PSIS_study``, ``L.PSIS_study``, ``r_knee_study`` / ``r_mknee_study``
  (lateral / medial femoral epicondyle), ``r_ankle_study`` / ``r_mankle_study`` (lateral /
  medial malleolus), ``r_toe_study``, ``r_5meta_study``, ``r_calc_study``, ``r_shoulder_study``
  (acromion), ``r_lelbow_study`` / ``r_melbow_study``, ``r_lwrist_study`` / ``r_mwrist_study``,
  ``C7_study``, and where present ``RHJC_study`` / ``LHJC_study`` (hip joint centres); the left
  side's start with ``L``.  Layout ``opencap``.
* **Vicon Plug-in Gait** (and tools that name markers as it does): ``LASI``, ``RASI``, ``LPSI``,
  ``RPSI`` (or ``SACR``), ``LKNE`` (lateral epicondyle; ``LMKNE`` / ``LKNM`` medial where
  placed), ``LANK`` (lateral malleolus; ``LMED`` / ``LMMA`` / ``LMANK`` medial), ``LHEE``,
  ``LTOE``, ``LSHO`` (acromion), ``LELB`` (lateral epicondyle; ``LMELB`` / ``LELM`` medial),
  ``LWRA`` / ``LWRB`` (radial / ulnar styloid), ``LFHD``, ``RFHD``, ``LBHD``, ``RBHD``.
  Layout ``plugingait``.

Joint centres (:func:`joint_centres`; all from the markers themselves, so any axes and either
handedness; lengths in the file's unit, ``metres_per_unit`` converting the constants below):

* hips: the file's hip joint centres where it has them (OpenCap's ``RHJC_study``), else the
  regression of Harrington, Morris, Engelbrecht, Jeffery & Bull (2007), "Prediction of the hip
  joint centre in adults, children, and patients with cerebral palsy based on magnetic resonance
  imaging", J. Biomech. 40(3):595-602, pelvis-only form: from the mid-ASIS, in the pelvis frame
  (lateral along the ASIS line, anterior square to it toward the mid-ASIS from the mid-PSIS,
  superior completing it, toward the shoulders, or away from the knees in a lower-body trial),
  ``anterior = -0.24 PD - 9.9 mm``, ``superior = -0.30 PW - 10.9 mm``, ``lateral = ±(0.33 PW + 7.3 mm)``;
  PW the ASIS-to-ASIS distance, PD the mid-ASIS-to-mid-PSIS distance (the take's medians: the pelvis
  is rigid).  The regression's error against MRI is the paper's; a marker's skin motion adds to it;
* knees, ankles, elbows, wrists: the midpoint of the lateral and medial (radial and ulnar)
  markers.  Where only the lateral marker is there (Plug-in Gait without medial markers) the
  centre is taken the subject's measured half width plus the marker's radius (a Vicon ``.mp`` /
  ``.vsk``, :mod:`.subject_params`, as Plug-in Gait does), else :data:`HALF_WIDTH`, medially of
  it: for the knee and ankle along the pelvis's left-right line, for the elbow along the line
  from the acromion to the hips' midpoint, each made square to the segment (and scaled by the
  sine of the angle between them).  That follows the epicondyles while the humerus and femur
  keep their neutral rotation (an arm hanging or held out sideways, a leg swinging); a thigh or
  upper arm turned in or out by an angle a puts the centre about ``2 HALF_WIDTH sin(a / 2)`` off
  (3 cm at 45°), and an arm raised forward is
  guessed half way between medial and down.  A medial marker removes the guess;
* shoulders: the glenohumeral centre :data:`SHOULDER_BELOW` of the acromia's distance below the
  acromion marker, along the trunk (mid-hips to mid-acromia) made square to the acromion line
  (Rab, Petuskey & Bagley 2002, "A method for determination of upper extremity kinematics",
  Gait & Posture 15(2):113-119).  The acromion moves with the shoulder girdle, the glenohumeral
  centre less so: a shrug or a reach lifts the estimate with the acromion;
* feet: the heel (``calc``, ``HEE``) and the toe markers (OpenCap's ``toe`` as the big toe and
  ``5meta`` as the small toe; Plug-in Gait's ``TOE``, on the second metatarsal head, as the
  toes' point);
* head (Plug-in Gait): the ears as the midpoints of each side's front and back head markers and
  the nose as the front markers' midpoint; the head joint is then placed below the ears as for
  any layout (:func:`.keypoint_layouts.body22_from_keypoints`).  Plug-in Gait's head markers sit
  on a band about the temples, a few centimetres above the ears: the head joint comes out that
  much high.  OpenCap has no head markers: the head follows the trunk (no twist);
* pelvis: the mid-ASIS and mid-PSIS (``SACR`` where there are no PSIS markers) as the points
  ``mid_asis`` and ``mid_psis``: a lower-body take's pelvis and trunk tilt forwards and back
  with them (:func:`.keypoint_layouts.pelvis_from_markers`, relative to
  :data:`.keypoint_layouts.PELVIS_NEUTRAL_TILT_DEG` of anterior tilt taken as upright);
* ``C7``, ``CLAV``, ``STRN``, ``T10`` and the thigh / shank clusters are not used (the neck
  and spine come from the hips and shoulders as for every layout).
"""
from __future__ import annotations

import re

import numpy as np

from .rotations import normalize

#: Harrington et al. (2007) pelvis-only regression, millimetres: (coefficient, constant) of
#: PD for the anterior, of PW for the superior and the lateral offset from the mid-ASIS
HARRINGTON_MM = {"anterior": (-0.24, -9.9), "superior": (-0.30, -10.9), "lateral": (0.33, 7.3)}
#: Rab et al. (2002): the glenohumeral centre lies this fraction of the acromia's distance below
#: the acromion marker
SHOULDER_BELOW = 0.17
#: metres from a lateral marker to the joint centre when the medial marker is missing: half a
#: typical adult width (knee 100 mm, ankle 70 mm, elbow 70 mm) plus a 14 mm marker's radius.  An
#: assumption, not a measurement: Plug-in Gait asks for each subject's widths
HALF_WIDTH = {"knee": 0.057, "ankle": 0.042, "elbow": 0.042}

_SIDES = {"left": "l", "right": "r"}

#: per marker set: role -> marker keys (``{s}``: the side's letter), first found wins; a role
#: with None for a key is optional
MARKER_SETS = {
    "opencap": {
        "asis": ("{s}_asis",), "psis": ("{s}_psis",), "hjc": ("{s}hjc",),
        "knee_lat": ("{s}_knee",), "knee_med": ("{s}_mknee",),
        "ankle_lat": ("{s}_ankle",), "ankle_med": ("{s}_mankle",),
        "shoulder": ("{s}_shoulder",),
        "elbow_lat": ("{s}_lelbow",), "elbow_med": ("{s}_melbow",),
        "wrist_lat": ("{s}_lwrist",), "wrist_med": ("{s}_mwrist",),
        "heel": ("{s}_calc",), "big_toe": ("{s}_toe",), "small_toe": ("{s}_5meta",),
    },
    "plugingait": {
        "asis": ("{s}asi",), "psis": ("{s}psi", "sacr"), "hjc": ("{s}hjc",),
        "knee_lat": ("{s}kne",), "knee_med": ("{s}mkne", "{s}knm", "{s}kne_med"),
        "ankle_lat": ("{s}ank",), "ankle_med": ("{s}med", "{s}mma", "{s}mank", "{s}ank_med"),
        "shoulder": ("{s}sho",),
        "elbow_lat": ("{s}elb",), "elbow_med": ("{s}melb", "{s}elm", "{s}elb_med"),
        "wrist_lat": ("{s}wra",), "wrist_med": ("{s}wrb",),
        "heel": ("{s}hee",), "foot_index": ("{s}toe",),
        "front_head": ("{s}fhd",), "back_head": ("{s}bhd",),
    },
}
#: roles every side must have (the rest are optional: medial markers, the file's hip centres)
REQUIRED = {"opencap": ("asis", "psis", "knee_lat", "knee_med", "ankle_lat", "ankle_med", "shoulder",
                        "elbow_lat", "elbow_med", "wrist_lat", "wrist_med", "heel", "big_toe", "small_toe"),
            "plugingait": ("asis", "psis", "knee_lat", "ankle_lat", "shoulder", "elbow_lat", "wrist_lat",
                            "wrist_med", "heel", "foot_index", "front_head", "back_head")}


def marker_key(name) -> str:
    """A marker's name as the key :data:`MARKER_SETS` uses: ``"r.ASIS_study"`` → ``"r_asis"``,
    ``"Subject1:LASI"`` → ``"lasi"``, ``"RHJC_study"`` → ``"rhjc"``."""
    key = str(name).strip().rsplit(":", 1)[-1].lower().replace(".", "_").replace(" ", "_")
    return re.sub(r"_study$", "", key)


def marker_subject(name) -> str:
    """The ``Subject:`` prefix of a marker's name (``"Bob"`` of ``"Bob:LASI"``), ``""`` without one."""
    name = str(name).strip()
    return name.rsplit(":", 1)[0].strip() if ":" in name else ""


def _roles(keys, set_name):
    """``({(side, role): marker index}, [missing marker names])`` of ``keys`` (marker keys) for a set."""
    index = {k: i for i, k in reversed(list(enumerate(keys)))}
    found, missing = {}, []
    for side, s in _SIDES.items():
        for role, cands in MARKER_SETS[set_name].items():
            names = [c.format(s=s) for c in cands]
            hit = next((index[n] for n in names if n in index), None)
            if hit is not None:
                found[(side, role)] = hit
            elif role in REQUIRED[set_name]:
                missing.append(names[0])
    return found, missing


def detect_marker_set(names):
    """``(set name, missing)`` for the marker names of a file: the set of :data:`MARKER_SETS`
    with the fewest required markers missing (``missing``: their keys, empty when complete), or
    ``(None, [])`` when the names hold no ASIS marker of either set."""
    keys = [marker_key(n) for n in names]
    best = None
    for set_name in MARKER_SETS:
        found, missing = _roles(keys, set_name)
        if ("left", "asis") not in found and ("right", "asis") not in found:
            continue
        if best is None or len(missing) < len(best[1]):
            best = (set_name, missing)
    return best or (None, [])


def rules_used(names, set_name, offsets=None) -> str:
    """How :func:`joint_centres` places the joints of a file with these marker ``names``, in
    words for the read's report, e.g. ``"plugingait markers: hips by Harrington 2007, knees,
    ankles, elbows a typical half width from the lateral marker (no medial marker)"``;
    ``offsets`` as :func:`joint_centres` takes them (the subject's measured widths)."""
    found, _ = _roles([marker_key(n) for n in names], set_name)
    offsets = offsets or {}
    both = all((s, "hjc") in found for s in _SIDES)
    parts = ["hips from the file's hip centres" if both else "hips by Harrington 2007"]
    lateral_only = [j for j in HALF_WIDTH if not all((s, f"{j}_med") in found for s in _SIDES)]
    measured = [j for j in lateral_only if all((s, j) in offsets for s in _SIDES)]
    guessed = [j for j in lateral_only if j not in measured]
    if measured:
        parts.append(", ".join(f"{j}s" for j in measured) + " the subject's half width from the lateral marker "
                     "(no medial marker)")
    if guessed:
        parts.append(", ".join(f"{j}s" for j in guessed) + " a typical half width from the lateral marker "
                     "(no medial marker)")
    if set_name == "opencap":
        parts.append("no head markers: the head follows the trunk")
    return f"{set_name} markers: " + "; ".join(parts)


def _square(v, axis):
    """``v`` less its component along the unit ``axis``, normalised (per frame)."""
    return normalize(v - np.sum(v * axis, -1, keepdims=True) * axis)


def joint_centres(names, markers, metres_per_unit=1.0, set_name=None, offsets=None):
    """The joint centres of a marker set (see the module doc).

    names: the markers' names (K); markers: ``(T, K, 3)`` in the file's unit and axes, NaN where
    lost; metres_per_unit: the file's unit in metres (1000 mm: 0.001); offsets: ``{(side,
    joint): metres}`` from a lateral marker to its joint centre (side ``"left"`` / ``"right"``,
    joint ``"knee"``, ``"ankle"``, ``"elbow"``), the subject's measured half widths plus the
    marker's radius (:meth:`.subject_params.SubjectParams.offset`), replacing
    :data:`HALF_WIDTH` where given and the medial marker is missing.  Returns ``(set name,
    {point: (T, 3)})`` with the points of the layout of that name (``left_hip``, ``left_knee``,
    ..., the feet's points, ``mid_asis``, ``mid_psis`` and, for Plug-in Gait, ``left_ear``,
    ``right_ear``, ``nose``), in the
    file's unit and axes.  Raises ``ValueError`` naming the markers a set lacks."""
    M = np.asarray(markers, np.float64)
    keys = [marker_key(n) for n in names]
    if set_name is None:
        set_name, missing = detect_marker_set(names)
        if set_name is None:
            raise ValueError("no anatomical marker set (OpenCap's r.ASIS_study ..., Plug-in Gait's LASI ...)")
    found, missing = _roles(keys, set_name)
    if missing:
        raise ValueError(f"the {set_name} markers lack {', '.join(missing)}")

    def m(side, role):
        return M[:, found[(side, role)]] if (side, role) in found else None
    mm = 1e-3 / float(metres_per_unit)                  # one millimetre in the file's unit
    out = {}
    # pelvis frame (Harrington 2007): origin mid-ASIS, lateral to the right along the ASIS line
    la, ra = m("left", "asis"), m("right", "asis")
    mid_asis, mid_psis = 0.5 * (la + ra), 0.5 * (m("left", "psis") + m("right", "psis"))
    right = normalize(ra - la)
    anterior = _square(mid_asis - mid_psis, right)
    up = np.cross(right, anterior)
    la_sh, ra_sh = m("left", "shoulder"), m("right", "shoulder")
    mid_sh = 0.5 * (la_sh + ra_sh)
    # a left-handed file: the up found points away from the shoulders, or (a lower-body trial,
    # no shoulders) towards the knees
    to_sh = np.sum(up * (mid_sh - mid_asis), -1, keepdims=True)
    to_knees = np.sum(up * (0.5 * (m("left", "knee_lat") + m("right", "knee_lat")) - mid_asis), -1, keepdims=True)
    flip = np.where(np.isfinite(to_sh), to_sh < 0, to_knees > 0)
    up = np.where(flip, -up, up)
    PW = np.nanmedian(np.linalg.norm(ra - la, axis=-1)) / mm
    PD = np.nanmedian(np.linalg.norm(mid_asis - mid_psis, axis=-1)) / mm
    h = HARRINGTON_MM
    ant = (h["anterior"][0] * PD + h["anterior"][1]) * mm
    sup = (h["superior"][0] * PW + h["superior"][1]) * mm
    lat = (h["lateral"][0] * PW + h["lateral"][1]) * mm
    # the pelvis markers' midpoints: the keypoint solve reads the pelvis's forward tilt from them
    # (:func:`.keypoint_layouts.pelvis_from_markers`); each is left out (NaN) where the other is, so
    # a gap's filling (held at the take's ends, interpolated between) keeps them a pair: one held
    # while the other moves on would turn the pelvis, and the trunk on it, over
    pair = (np.isfinite(mid_asis).all(-1) & np.isfinite(mid_psis).all(-1))[:, None]
    out["mid_asis"], out["mid_psis"] = np.where(pair, mid_asis, np.nan), np.where(pair, mid_psis, np.nan)
    for side, sign in (("left", -1.0), ("right", 1.0)):
        hjc = m(side, "hjc")
        out[f"{side}_hip"] = hjc if hjc is not None else mid_asis + ant * anterior + sup * up + sign * lat * right
    # shoulders: below the acromion along the trunk made square to the acromion line (Rab 2002)
    sh_line = normalize(ra_sh - la_sh)
    trunk_up = _square(mid_sh - 0.5 * (out["left_hip"] + out["right_hip"]), sh_line)
    width = np.linalg.norm(ra_sh - la_sh, axis=-1, keepdims=True)
    for side in ("left", "right"):
        out[f"{side}_shoulder"] = m(side, "shoulder") - SHOULDER_BELOW * width * trunk_up

    def centre(side, joint, proximal, towards):
        """The centre from the lateral and medial markers, else the subject's offset (else
        ``HALF_WIDTH``) from the lateral one, scaled by the sine of the angle between
        ``towards`` (a per-frame vector pointing medially) and the bone: in the plane of
        ``towards`` and the proximal centre's line to the marker, on the medial side, the offset
        square to the bone (proximal centre to joint centre, as Plug-in Gait's chord), not to
        the line to the marker (that put the centre about ``offset² / bone`` distal: 7 mm at a
        knee)."""
        lat_m, med_m = m(side, f"{joint}_lat"), m(side, f"{joint}_med")
        if med_m is not None:
            return 0.5 * (lat_m + med_m)
        seg = lat_m - proximal
        L = np.linalg.norm(seg, axis=-1, keepdims=True)
        v, a = normalize(towards), seg / L
        w = normalize(v - np.sum(v * a, -1, keepdims=True) * a)     # medial, square to the segment
        dist = (offsets or {}).get((side, joint), HALF_WIDTH[joint]) / float(metres_per_unit)
        # the right triangle proximal - centre - marker: hypotenuse L, the offset d opposite the
        # angle t at the proximal centre; d = dist times the sine of the angle between `towards`
        # and the bone (proximal to centre), found by a few fixed-point steps from t = 0
        sin_t, cos_t = np.zeros_like(L), np.ones_like(L)
        for _ in range(4):
            u = cos_t * a + sin_t * w
            sine = np.sqrt(np.clip(1.0 - np.sum(v * u, -1, keepdims=True) ** 2, 0.0, 1.0))
            sin_t = np.clip(dist * sine / L, 0.0, 1.0)
            cos_t = np.sqrt(1.0 - sin_t ** 2)
        return proximal + L * cos_t * (cos_t * a + sin_t * w)
    mid_hips = 0.5 * (out["left_hip"] + out["right_hip"])
    for side, sign in (("left", 1.0), ("right", -1.0)):
        # legs: toward the other side along the pelvis's left-right line; arms: toward the
        # hips' midpoint (medial for an arm hanging, downward for one held out sideways)
        out[f"{side}_knee"] = centre(side, "knee", out[f"{side}_hip"], sign * right)
        out[f"{side}_ankle"] = centre(side, "ankle", out[f"{side}_knee"], sign * right)
        out[f"{side}_elbow"] = centre(side, "elbow", out[f"{side}_shoulder"], mid_hips - m(side, "shoulder"))
        out[f"{side}_wrist"] = 0.5 * (m(side, "wrist_lat") + m(side, "wrist_med"))
        out[f"{side}_heel"] = m(side, "heel")
        if set_name == "opencap":
            out[f"{side}_big_toe"], out[f"{side}_small_toe"] = m(side, "big_toe"), m(side, "small_toe")
        else:
            out[f"{side}_foot_index"] = m(side, "foot_index")
            out[f"{side}_ear"] = 0.5 * (m(side, "front_head") + m(side, "back_head"))
    if set_name == "plugingait":
        out["nose"] = 0.5 * (m("left", "front_head") + m("right", "front_head"))
    return set_name, out
