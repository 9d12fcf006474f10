"""Training data: BVH sources -> cached ground-truth clips -> window batches.

Cache (:func:`build_cache`)
---------------------------
Every BVH from :func:`core.bvh.iter_bvh_sources` (a folder, a file or a tar
archive such as ``bandai-namco-motion.tar.xz``) is

1. read (:func:`core.bvh.read_bvh`) and mapped onto the 22-joint body
   (:func:`core.joint_maps.clip_to_body_motion`: positions in metres,
   Blender axes, floor z = 0, world orientations of the pelvis, head, wrists
   and ankles, a :class:`~core.skeleton.Body` with the clip's own bone
   lengths, a take id);
2. resampled to the model rate (30 fps; positions linearly, orientations by
   slerp) when the file has another rate;
3. solved by :func:`core.hybrik.ik_from_positions` (adaptive HybrIK with the
   end orientations) into local rotations whose limbs are biomechanical
   (hinge elbows/knees within limits, elbow twist clamped): this, posed by FK
   on the clip's body, *is* the ground truth the network learns;
4. stored as one ``.npz`` per clip (float32 where possible): ``offsets``
   (22, 3), ``root_rest`` (3,), ``stature``, ``local_quat`` (T, 22, 4) wxyz
   (sign-continuous over time), ``root_pos`` (T, 3), ``swivel`` (T, 4)
   radians (LIMB_NAMES order), ``contacts`` (T, 2) uint8 (left, right),
   ``fps``, ``name``, ``take_id``, ``source``.

Foot contacts: a foot is in contact on a frame when its ankle joint **or**
its foot (ball) joint moves slower than ``CONTACT_SPEED`` = 0.25 m/s
horizontally (central differences) **and** is within ``CONTACT_HEIGHT`` =
6 cm of that joint type's lowest height in the clip (the 1st percentile of
both sides' heights, so a single glitch frame cannot set the reference).

The cache lives outside the repository: ``$BLENDER_MANIKIN_CACHE/dataset``
or ``~/.cache/blender_manikin/dataset``, in a folder named by a hash of the
source (absolute path, size and mtime of the archive/file, or of every BVH
in a folder), of :data:`PREPROCESS_VERSION` and of the code (syntax tree
without docstrings) of the core modules the ground truth depends on.  ``index.json`` is written last;
when it exists a second call returns the clip files without reading any
BVH.  An interrupted build keeps the clips it finished.

Split
-----
Whole takes are held out: a clip is in the validation set when
``int(sha1(take_id).hexdigest(), 16) % 100 < VAL_PERCENT`` (10).  This is
deterministic, independent of the order or number of files, and keeps every
clip of a take on the same side.  When that leaves the validation set empty
(tiny sources) the take with the smallest bucket goes to validation; with a
single take validation reuses the training clips (flagged in the JSON).
``split.json`` in the cache lists both sides.

Windows (:class:`WindowSampler`)
--------------------------------
A window is W frames (default 40 at 30 fps) of one clip, the clip chosen
with probability proportional to its length, the start uniformly.  Ground
truth is posed by FK; tracker inputs are synthesised from it (head joint,
wrist joints, optionally pelvis and ankles: 6-DoF each) and fed through
:func:`core.features.make_inputs`; targets through
:func:`core.features.encode_targets`.  Augmentation (training only): the
window is time-resampled by a factor 0.8-1.25 (log-uniform; slerp/linear),
with probability 5 % shifted against the clip's edge and edge-padded the
way inference pads, uniform body scale 0.85-1.15 (offsets and positions),
floor offset ±2 cm, tracker noise (positions σ = 4 mm, orientations 2° rms,
per frame) and a constant per-window orientation offset of the hand
trackers (random axis, up to 5°).
"""
from __future__ import annotations

import hashlib
import json
import math
import multiprocessing as mp
import os
import re
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core import features
from ..core.devices import HAND_DEVICES
from ..core import hybrik
from ..core import limb_solver as ls
from ..core import rotations as rot
from ..core.skeleton import (MIRROR_JOINTS, MIRROR_M, PARENTS, PROPORTIONS, SOLE, Body, J, LIMBS,
                             NUM_JOINTS, forward_kinematics, make_body)

#: bump when the stored ground truth changes meaning
PREPROCESS_VERSION = 1
MODEL_FPS = 30.0
VAL_PERCENT = 10
CONTACT_SPEED = 0.25      # m/s, horizontal
CONTACT_HEIGHT = 0.06     # m above the clip's lowest height of that joint type
#: core modules whose source is part of the cache key (per source format)
_KEY_MODULES = ("bvh.py", "joint_maps.py", "hybrik.py", "limb_solver.py", "skeleton.py")
_FORMAT_KEY_MODULES = {"bvh": (), "asf_amc": ("asf_amc.py",)}
#: file name endings of each motion format (what a folder's fingerprint covers)
_FORMAT_SUFFIXES = {"bvh": (".bvh", ".bvh.gz"), "asf_amc": (".amc", ".amc.gz", ".asf", ".asf.gz")}

_CORE_DIR = Path(__file__).resolve().parent.parent / "core"
_END_JOINTS = (J["pelvis"], J["head"], J["left_wrist"], J["right_wrist"], J["left_ankle"], J["right_ankle"])


@dataclass
class MotionSource:
    """One training (or selection) source and how to read it.

    path: a folder, a file or a tar archive of BVH or ASF/AMC takes.  name: what the model card
    calls it (default: the file name).  joint_map: ``"bandai"``, ``"cmu"`` (cgspeed BVH),
    ``"mixamo"``, ``"lafan1"``, ``"100style"`` (also Xsens MVN BVH), ``"neuron"`` (Perception
    Neuron), ``"rokoko"`` (Rokoko Studio), ``"cmu_asf"`` (CMU/HDM05 ASF), a joint-map
    ``.json`` file (:func:`core.joint_maps.load_joint_map`; relative to the sources file) or
    ``None`` (detected from the joint names).  unit_scale:
    metres per source unit, ``"auto"``, or ``None`` (the map's).  up / forward: the source's
    up and facing axes (``"y"``, ``"z"``, ...; ``None``: the map's).  fps: the takes' frame rate
    (AMC, which does not state it: default 120; BVH: replaces the files' Frame Time).  licence:
    the data's licence, as the model card must quote it.
    """
    path: str
    name: str | None = None
    joint_map: str | None = None
    unit_scale: float | str | None = None
    up: str | None = None
    forward: str | None = None
    fps: float | None = None
    licence: str | None = None

    @property
    def label(self):
        return self.name or os.path.basename(os.path.abspath(self.path))

    def read_options(self):
        """The options that change the cached ground truth (part of the cache key)."""
        opts = {k: getattr(self, k) for k in ("joint_map", "unit_scale", "up", "forward", "fps")
                if getattr(self, k) is not None}
        jm = opts.get("joint_map")
        if isinstance(jm, str) and jm.lower().endswith(".json") and os.path.isfile(jm):
            with open(jm, "rb") as f:      # an edited joint-map file makes new ground truth
                opts["joint_map_sha1"] = hashlib.sha1(f.read()).hexdigest()
        return opts


#: licences of the sources this project knows by name (the sources file can state any other)
KNOWN_LICENCES = {
    "bandai": "CC BY-NC-ND 4.0 (Bandai Namco Research Motiondataset; non-commercial, no derivatives)",
    "hdm05": "CC BY-SA 3.0 (HDM05; share-alike)",
    "cmu": "CMU Graphics Lab Motion Capture Database: free for all uses",
    "lafan1": "CC BY-NC-ND 4.0 (Ubisoft La Forge LaFAN1; non-commercial, no derivatives)",
    "100style": "CC BY 4.0 (100STYLE, Mason et al. 2022; attribution, commercial use allowed)",
}


def source_licence(src):
    """The licence of a :class:`MotionSource`: as stated, else from its known name, else unknown."""
    if src.licence:
        return src.licence
    low = src.label.lower()
    for key, text in KNOWN_LICENCES.items():
        if key in low:
            return text
    return "unknown: state it in the sources file"


#: licences that allow any use, commercial included (what :func:`combined_licence` may rank lowest)
_PERMISSIVE_LICENCE = re.compile(r"\bCC0\b|PUBLIC DOMAIN|\bCC[ -]BY(?![ -]?(NC|ND|SA)\b)\b|FREE FOR (ALL|ANY) USES?\b")


def licence_rank(text):
    """How restrictive a data licence is: 5 unknown, 4 NoDerivatives, 3 NonCommercial, 2 terms
    not recognised (may forbid commercial use), 1 ShareAlike, 0 known to allow any use
    (CC0, public domain, CC BY, "free for all uses")."""
    t = " ".join(str(text).upper().replace("_", " ").split())
    flat = re.sub(r"[^A-Z0-9]", "", t)
    if t.startswith("UNKNOWN"):
        return 5
    if re.search(r"-ND\b", t) or "NODERIV" in flat:
        return 4
    if re.search(r"(^|[^A-Z])NC([^A-Z]|$)", t) or "NONCOMMERCIAL" in flat:
        return 3
    if re.search(r"-SA\b", t) or "SHAREALIKE" in flat:
        return 1
    return 0 if _PERMISSIVE_LICENCE.search(t) else 2


def combined_licence(licences):
    """The most restrictive of several data licences (the weights follow it):
    :func:`licence_rank`; terms it does not recognise count as possibly non-commercial, never as
    permissive; of equally restrictive ones, the first."""
    return max(licences, key=licence_rank) if licences else "unknown"


def _entry_lines(text):
    """Line of each element of the JSON list ``text`` (already known to be valid JSON)."""
    dec, lines = json.JSONDecoder(), []
    i = text.index("[") + 1
    while True:
        i = re.compile(r"[\s,]*").match(text, i).end()
        if i >= len(text) or text[i] == "]":
            return lines
        lines.append(text.count("\n", 0, i) + 1)
        i = dec.raw_decode(text, i)[1]


def _check_source(src):
    """The problem with a :class:`MotionSource`'s reading options, or ``None``."""
    from ..core import joint_maps

    def number(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    for k in ("path", "name", "licence"):
        v = getattr(src, k)
        if not (v is None and k != "path") and not (isinstance(v, str) and v.strip()):
            return f"{k} must be a non-empty string, got {v!r}"
    maps = sorted(set(joint_maps.JOINT_MAPS) | {"cmu_asf"})
    if isinstance(src.joint_map, str) and src.joint_map.lower().endswith(".json"):
        try:
            joint_maps.load_joint_map(src.joint_map)
        except ValueError as exc:
            return f"joint_map file: {exc}"
    elif src.joint_map is not None and src.joint_map not in maps:
        return (f"unknown joint_map {src.joint_map!r} (expected one of {', '.join(maps)} "
                "or a joint-map .json file)")
    u = src.unit_scale
    if u is not None and not (number(u) and u > 0) and not (isinstance(u, str) and (
            u == "auto" or u in joint_maps.UNIT_CANDIDATES)):
        return (f"unit_scale must be metres per unit (a positive number), 'auto' or one of "
                f"{', '.join(joint_maps.UNIT_CANDIDATES)}; got {u!r}")
    for k in ("up", "forward"):
        v = getattr(src, k)
        if v is not None and not (isinstance(v, str) and re.fullmatch(r"[+-]?[xyzXYZ]", v.strip())):
            return f"{k} must be an axis such as 'y', '-z'; got {v!r}"
    if src.up is not None and src.forward is not None:
        try:
            joint_maps.axis_conversion(src.up, src.forward)
        except ValueError as exc:
            return str(exc)
    if src.fps is not None and not (number(src.fps) and src.fps > 0):
        return f"fps must be a positive number, got {src.fps!r}"
    return None


def load_sources(path):
    """:class:`MotionSource` list from a JSON file (a list of objects with the fields above;
    relative paths are relative to the file).  Errors name the file, the line and the entry:
    ``sources.json line 3: source 2: unknown joint_map 'cmu-asf' (...)``."""
    from ..core.recording import read_text
    text = read_text(path)          # a BOM or UTF-16 read; a bad byte named with its line
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(data, list) or not data:
        raise ValueError(f"{path}: expected a non-empty JSON list of sources")
    lines = _entry_lines(text)
    fields = set(MotionSource.__dataclass_fields__)
    out = []
    for i, entry in enumerate(data):
        where = f"{path} line {lines[i]}: source {i + 1}"
        if not isinstance(entry, dict) or "path" not in entry:
            raise ValueError(f"{where} must be an object with a 'path'")
        unknown = sorted(set(entry) - fields)
        if unknown:
            raise ValueError(f"{where}: unknown field(s) {', '.join(unknown)} "
                             f"(expected {', '.join(sorted(fields))})")
        src = MotionSource(**entry)
        jm = src.joint_map
        if isinstance(jm, str) and jm.lower().endswith(".json"):      # relative to the sources file
            jm = os.path.expanduser(jm)
            src.joint_map = jm if os.path.isabs(jm) else os.path.join(os.path.dirname(os.path.abspath(path)), jm)
        elif isinstance(jm, str):                # a built-in map's name in any case: "LaFAN1"
            src.joint_map = jm.strip().lower()
        problem = _check_source(src)
        if problem:
            raise ValueError(f"{where}: {problem}")
        src.path = os.path.expanduser(src.path)
        if not os.path.isabs(src.path):
            src.path = os.path.join(os.path.dirname(os.path.abspath(path)), src.path)
        out.append(src)
    return out


def as_source(source):
    return source if isinstance(source, MotionSource) else MotionSource(path=os.fspath(source))


def default_cache_root():
    base = os.environ.get("BLENDER_MANIKIN_CACHE") or os.path.join(os.path.expanduser("~"), ".cache",
                                                                    "blender_manikin")
    return os.path.join(base, "dataset")


def _log(msg):
    print(msg, file=sys.stderr, flush=True)


# --------------------------------------------------------------------------
# cache key
def source_format(source):
    """``"bvh"`` or ``"asf_amc"`` (Acclaim, as CMU and HDM05 ship): what a folder, file or tar
    archive of motion holds (an archive is judged by its first members)."""
    p = Path(source)
    names = []
    if p.is_dir():
        names = [x.name for x in p.rglob("*") if x.is_file()]
    elif p.is_file() and not p.name.lower().endswith(_FORMAT_SUFFIXES["bvh"] + _FORMAT_SUFFIXES["asf_amc"]):
        import tarfile
        try:
            with tarfile.open(p, mode="r|*") as tf:
                for i, m in enumerate(tf):
                    names.append(m.name)
                    if i > 200 or m.name.lower().endswith(_FORMAT_SUFFIXES["bvh"] + (".amc", ".amc.gz")):
                        break
        except tarfile.TarError:
            return "bvh"
    else:
        names = [p.name]
    low = [n.lower() for n in names]
    if any(n.endswith((".amc", ".amc.gz")) for n in low) and not any(n.endswith(_FORMAT_SUFFIXES["bvh"]) for n in low):
        return "asf_amc"
    return "bvh"


def _source_fingerprint(source):
    p = Path(source).resolve()
    h = hashlib.sha1(str(p).encode())
    suffixes = _FORMAT_SUFFIXES["bvh"] + _FORMAT_SUFFIXES["asf_amc"]
    if p.is_dir():
        for f in sorted(x for x in p.rglob("*") if x.is_file() and x.name.lower().endswith(suffixes)):
            st = f.stat()
            h.update(f"{f.relative_to(p).as_posix()}|{st.st_size}|{st.st_mtime_ns}\n".encode())
    else:
        st = p.stat()
        h.update(f"|{st.st_size}|{st.st_mtime_ns}".encode())
    return h.hexdigest()


def _code_digest(path):
    """Digest of a module's code: its AST without docstrings, so edits of
    comments, docstrings or formatting keep the cache."""
    import ast
    src = path.read_text(encoding="utf-8")
    try:
        tree = ast.parse(src)
    except SyntaxError:
        return hashlib.sha1(src.encode()).hexdigest()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(body, list) and body and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return hashlib.sha1(ast.dump(tree, include_attributes=False).encode()).hexdigest()


def code_version(fmt="bvh"):
    """Hash of PREPROCESS_VERSION and the code of the core modules the ground truth depends on."""
    h = hashlib.sha1(f"preprocess={PREPROCESS_VERSION};fps={MODEL_FPS}".encode())
    if fmt != "bvh":
        h.update(f"format={fmt}".encode())
    for m in _KEY_MODULES + _FORMAT_KEY_MODULES.get(fmt, ()):
        f = _CORE_DIR / m
        h.update(m.encode())
        if f.exists():
            h.update(_code_digest(f).encode())
    return h.hexdigest()[:12]


def cache_key(source, fps=MODEL_FPS, fmt="bvh"):
    src = as_source(source)
    opts = src.read_options()
    h = hashlib.sha1(f"{_source_fingerprint(src.path)}|{code_version(fmt)}|{float(fps)}".encode())
    if opts:
        h.update(json.dumps(opts, sort_keys=True).encode())
    return h.hexdigest()[:16]


def cache_dir_for(source, cache_dir=None, fps=MODEL_FPS, fmt=None):
    src = as_source(source)
    root = cache_dir or default_cache_root()
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(src.path).name)[:40] or "source"
    return os.path.join(root, f"{stem}-{cache_key(src, fps, fmt or source_format(src.path))}")


# --------------------------------------------------------------------------
# per-clip processing
def _resample(positions, rots, fps_in, fps_out):
    """Positions ``(T, 22, 3)`` linear, dict of ``(T, 3, 3)`` slerp; same time span."""
    T = positions.shape[0]
    t_in = np.arange(T) / fps_in
    n_out = int(np.floor(t_in[-1] * fps_out + 1e-9)) + 1
    t = np.arange(n_out) / fps_out * fps_in            # in input frames
    i0 = np.clip(np.floor(t).astype(int), 0, max(T - 2, 0))
    i1 = np.minimum(i0 + 1, T - 1)
    w = np.clip(t - i0, 0.0, 1.0)
    pos = positions[i0] * (1 - w)[:, None, None] + positions[i1] * w[:, None, None]
    out = {}
    for j, R in rots.items():
        q = rot.quat_continuous(rot.matrix_to_quat(R))
        out[j] = rot.quat_to_matrix(rot.quat_slerp(q[i0], q[i1], w))
    return pos, out


def foot_contacts(positions, fps, speed=CONTACT_SPEED, height=CONTACT_HEIGHT):
    """``(T, 2)`` uint8 contacts (left, right) from joint positions ``(T, 22, 3)`` (see module doc)."""
    P = np.asarray(positions, np.float64)
    T = P.shape[0]
    out = np.zeros((T, 2), bool)
    for a, b in ((J["left_ankle"], J["right_ankle"]), (J["left_foot"], J["right_foot"])):
        z_ref = np.percentile(P[:, [a, b], 2], 1.0) if T else 0.0
        for side, j in enumerate((a, b)):
            p = P[:, j]
            if T > 1:
                v = np.gradient(p[:, :2], axis=0) * fps
                v = np.linalg.norm(v, axis=-1)
            else:
                v = np.zeros(T)
            out[:, side] |= (v < speed) & (p[:, 2] < z_ref + height)
    return out.astype(np.uint8)


def _end_rotations(mc):
    """World orientations ``{joint index: (T, 3, 3)}`` of a MotionClip (tolerant of field names)."""
    for attr in ("end_rot", "rotations", "world_rot", "orientations", "rot"):
        val = getattr(mc, attr, None)
        if val is None:
            continue
        if isinstance(val, dict):
            out = {}
            for k, R in val.items():
                j = J[k] if isinstance(k, str) else int(k)
                if j in _END_JOINTS:
                    out[j] = np.asarray(R, np.float64)
            return out
        arr = np.asarray(val, np.float64)
        if arr.ndim == 4 and arr.shape[1] == NUM_JOINTS:
            return {j: arr[:, j] for j in _END_JOINTS if np.isfinite(arr[:, j]).all()}
    raise ValueError(f"MotionClip has no world rotations of the end joints (fields: {list(vars(mc))})")


def motion_to_record(mc, name, source_label, fps=MODEL_FPS):
    """Ground-truth arrays of one MotionClip (see module doc) as a dict for ``np.savez``."""
    positions = np.asarray(mc.positions, np.float64)
    ends = _end_rotations(mc)
    fps_in = float(mc.fps)
    if abs(fps_in - fps) > 1e-3:
        positions, ends = _resample(positions, ends, fps_in, fps)
    body = mc.body
    res = hybrik.ik_from_positions(positions, body, end_rot=ends)
    quat = rot.quat_continuous(rot.matrix_to_quat(res.local_rot))
    contacts = foot_contacts(res.positions, fps)
    err = np.linalg.norm(res.positions - positions, axis=-1)
    return dict(
        name=np.str_(name), take_id=np.str_(str(getattr(mc, "take_id", name))),
        source=np.str_(source_label), fps=np.float32(fps),
        offsets=np.asarray(body.offsets, np.float32), root_rest=np.asarray(body.root_rest, np.float32),
        stature=np.float32(body.stature), local_quat=quat.astype(np.float32),
        root_pos=res.root_pos.astype(np.float32), swivel=res.swivel.astype(np.float32),
        contacts=contacts, ik_error_mean=np.float32(err.mean()), ik_error_max=np.float32(err.max()),
    )


def _safe_name(name):
    base = re.sub(r"\.bvh(\.gz)?$", "", name, flags=re.IGNORECASE)
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", base)[:120] + "-" + hashlib.sha1(name.encode()).hexdigest()[:8]


def _process(job):
    """Worker: parse one take (BVH bytes, or AMC and ASF bytes), map, solve, write its npz.
    Returns index info or an error."""
    name, data, clips_dir, source_label, fps, opts = job
    import io
    from ..core import bvh, joint_maps
    out = os.path.join(clips_dir, _safe_name(name) + ".npz")
    try:
        if os.path.exists(out):          # finished by an interrupted earlier build
            with np.load(out) as z:
                return dict(file=os.path.basename(out), name=name, take_id=str(z["take_id"]),
                            frames=int(z["local_quat"].shape[0]), ik_error_mean=float(z["ik_error_mean"]))
        if isinstance(data, tuple):      # ("asf_amc", amc bytes, asf name, asf bytes)
            from ..core import asf_amc
            _, amc, asf_name, asf = data
            skel = asf_amc.read_asf(io.BytesIO(asf), asf_name)
            clip = asf_amc.read_amc(io.BytesIO(amc), skel, name=name, fps=float(opts.get("fps") or 120.0))
            jm = opts.get("joint_map")
            mc = joint_maps.clip_to_body_motion(
                clip, asf_amc.asf_joint_map(skel) if jm in (None, "cmu_asf") else jm,
                unit_scale=opts.get("unit_scale"), up=opts.get("up"), forward=opts.get("forward"))
        else:
            clip = bvh.read_bvh(io.BytesIO(data), name)
            if opts.get("fps"):          # the sources file's rate replaces the Frame Time
                clip.frame_time = 1.0 / float(opts["fps"])
            mc = joint_maps.clip_to_body_motion(clip, opts.get("joint_map"), unit_scale=opts.get("unit_scale"),
                                                up=opts.get("up"), forward=opts.get("forward"))
        if mc is None or np.asarray(mc.positions).shape[0] < 2:
            return dict(name=name, error="fewer than 2 frames")
        rec = motion_to_record(mc, name, source_label, fps)
        tmp = out + f".tmp{os.getpid()}.npz"
        np.savez(tmp, **rec)
        os.replace(tmp, out)
        return dict(file=os.path.basename(out), name=name, take_id=str(rec["take_id"]),
                    frames=int(rec["local_quat"].shape[0]), ik_error_mean=float(rec["ik_error_mean"]))
    except Exception as exc:  # a bad file must not stop the build
        return dict(name=name, error=f"{type(exc).__name__}: {exc}")


# --------------------------------------------------------------------------
# split
def take_bucket(take_id):
    return int(hashlib.sha1(str(take_id).encode("utf-8")).hexdigest(), 16) % 100


def make_split(clips, val_percent=VAL_PERCENT):
    """``{"train": [files], "val": [files], ...}`` from index entries (see module doc)."""
    takes = sorted({c["take_id"] for c in clips})
    val_takes = {t for t in takes if take_bucket(t) < val_percent}
    note = f"sha1(take_id) % 100 < {val_percent} -> validation"
    if not val_takes and len(takes) > 1:
        val_takes = {min(takes, key=lambda t: (take_bucket(t), t))}
        note += "; no take fell in the bucket, so the take with the smallest bucket was held out"
    train = [c["file"] for c in clips if c["take_id"] not in val_takes]
    val = [c["file"] for c in clips if c["take_id"] in val_takes]
    val_is_train = False
    if not val:
        val, val_is_train = list(train), True
        note += "; a single take: validation reuses the training clips"
    frames = {c["file"]: c["frames"] for c in clips}
    return dict(rule=note, val_percent=val_percent, val_is_train=val_is_train,
                train_takes=len(set(takes) - val_takes) if not val_is_train else len(takes),
                val_takes=len(val_takes) if not val_is_train else len(takes),
                train_frames=int(sum(frames[f] for f in train)), val_frames=int(sum(frames[f] for f in val)),
                train=train, val=val)


# --------------------------------------------------------------------------
def build_cache(source, cache_dir=None, fps=MODEL_FPS, workers=2, verbose=True):
    """Parse, solve and cache every take (BVH or ASF/AMC) of ``source`` (a path or a
    :class:`MotionSource`); returns the clip ``.npz`` paths.

    ``cache_dir``: the cache *root* (default :func:`default_cache_root`); the
    clips go to ``<root>/<name>-<hash>/clips``.  A second call with the same
    source, options and code returns at once without reading any file.
    """
    src = as_source(source)
    source = src.path
    opts = src.read_options()
    if not os.path.exists(source):
        raise FileNotFoundError(f"motion source not found: {source}")
    fmt = source_format(source)
    d = cache_dir_for(src, cache_dir, fps, fmt)
    index_path = os.path.join(d, "index.json")
    if os.path.exists(index_path):
        with open(index_path) as f:
            index = json.load(f)
        if verbose:
            _log(f"[dataset] cache hit: {d} ({len(index['clips'])} clips, {index['frames']} frames)")
        return [os.path.join(d, "clips", c["file"]) for c in index["clips"]]

    from ..core import bvh
    clips_dir = os.path.join(d, "clips")
    os.makedirs(clips_dir, exist_ok=True)
    label = src.label
    t0 = time.time()
    is_archive = os.path.isfile(source) and not source.lower().endswith((".bvh", ".bvh.gz"))
    if fmt == "asf_amc":
        from ..core import asf_amc

        def _asf_job(name, take):
            asf = take.open_asf().read() if take.open_asf is not None else b""
            return (name, ("asf_amc", take.open_amc().read(), take.asf_name or "", asf), clips_dir, label,
                    float(fps), opts)
        jobs = (_asf_job(name, s) for name, s in asf_amc.iter_asf_amc_sources(source))
    else:
        jobs = ((name, opener().read(), clips_dir, label, float(fps), opts)
                for name, opener in bvh.iter_bvh_sources(source, **({"sort": False} if is_archive else {})))
    results, errors, frames, last = [], [], 0, 0.0
    if verbose:
        _log(f"[dataset] building cache {d} from {source} ({workers} workers)")

    def consume(it):
        nonlocal frames, last
        for r in it:
            if "error" in r:
                errors.append(r)
                if verbose:
                    _log(f"[dataset] skipped {r['name']}: {r['error']}")
                continue
            results.append(r)
            frames += r["frames"]
            now = time.time()
            if verbose and (now - last > 2.0):
                last = now
                _log(f"[dataset] {len(results)} clips, {frames} frames, {now - t0:.0f} s")

    if workers and workers > 1:
        ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else mp.get_context()
        with ctx.Pool(workers) as pool:
            consume(pool.imap_unordered(_process, jobs, chunksize=2))
    else:
        consume(map(_process, jobs))
    if not results:
        raise RuntimeError(f"no usable BVH clips in {source}"
                           + (f" ({len(errors)} failed, first: {errors[0]['error']})" if errors else ""))
    results.sort(key=lambda r: r["name"])
    split = make_split(results)
    elapsed = time.time() - t0
    index = dict(source=os.path.abspath(source), source_name=label, fps=float(fps), format=fmt, options=opts,
                 code_version=code_version(fmt), preprocess_version=PREPROCESS_VERSION,
                 clips=results, frames=int(frames), skipped=errors, build_seconds=round(elapsed, 1),
                 contact_rule=dict(speed_mps=CONTACT_SPEED, height_m=CONTACT_HEIGHT))
    with open(os.path.join(d, "split.json"), "w", newline="\n") as f:
        json.dump(split, f, indent=1)
    tmp = index_path + ".tmp"
    with open(tmp, "w", newline="\n") as f:
        json.dump(index, f, indent=1)
    os.replace(tmp, index_path)
    if verbose:
        _log(f"[dataset] done: {len(results)} clips, {frames} frames ({frames / fps / 3600:.2f} h), "
             f"{len(errors)} skipped, {elapsed:.0f} s; split: {len(split['train'])} train / "
             f"{len(split['val'])} val clips ({split['val_takes']} val takes)")
    return [os.path.join(d, "clips", r["file"]) for r in results]


def load_index(clip_files):
    """``(index, split)`` dicts of the cache the clip files belong to."""
    d = os.path.dirname(os.path.dirname(os.path.abspath(clip_files[0])))
    with open(os.path.join(d, "index.json")) as f:
        index = json.load(f)
    with open(os.path.join(d, "split.json")) as f:
        split = json.load(f)
    return index, split


def split_files(clip_files):
    """``(train_files, val_files, split)`` for clip files of one cache."""
    _, split = load_index(clip_files)
    d = os.path.dirname(os.path.abspath(clip_files[0]))
    return ([os.path.join(d, f) for f in split["train"]], [os.path.join(d, f) for f in split["val"]], split)


#: motion class patterns of take names: HDM05 (``HDM_<actor>_<class><digits>...``) and the
#: Bandai Namco takes (``dataset-<n>_<class>_<style>_<nnn>``)
MOTION_CLASS_PATTERNS = (re.compile(r"HDM_[a-z]+_([A-Za-z]+)"), re.compile(r"dataset-\d+_([a-z-]+)_"))


def motion_class(name):
    """The motion class in a take's name, path or cache file name (HDM05
    ``HDM_bd_squat1Reps_001_120.amc`` -> ``"squat"``, Bandai ``dataset-1_walk_active_001.bvh`` ->
    ``"walk"``), or ``None`` when the name follows neither convention."""
    found = [m for pat in MOTION_CLASS_PATTERNS for m in pat.findall(os.path.basename(str(name)))]
    return found[-1] if found else None   # cache names hold the folder ("dataset-1_data_") first


def motion_group(name):
    """The sampling group of a take (:class:`WindowSampler` ``balance``): its motion class
    (:func:`motion_class`), else its file stem without a final take number (CMU ``01_02.amc`` ->
    ``"01"``, a subject's session), else the stem itself (a group of one take)."""
    cls = motion_class(name)
    if cls is not None:
        return cls
    stem = os.path.splitext(os.path.basename(str(name)))[0]
    return re.sub(r"[_\-. ]*\d+$", "", stem) or stem


# --------------------------------------------------------------------------
# windows
@dataclass
class Augment:
    """Training augmentation (see module doc); ``Augment.off()`` disables all.

    speed: time-resampling factor range (log-uniform).  stature: the body's
    stature after retargeting, metres (uniform); ``None`` keeps the clip's.
    segment: each segment group (legs, thigh vs shank, torso, neck and head,
    arms, shoulder width, hip width) is scaled by its own factor in
    ``[1 - segment, 1 + segment]`` (log-uniform) before the stature is set.
    floor: uniform floor offset (metres).  mirror: probability of a
    left/right mirrored window.  head_offset: metres, per axis, of a constant
    offset of the head input in the head's frame (eye or HMD versus head
    joint).  calibration: probability that the window holds a synthetic
    T-pose or A-pose (:func:`calibration_pose`) blended into the motion.
    arm_mix: probability that the window's arms (collars down) are another
    window's, so the legs cannot be guessed from what the arms do (a saber
    swing says nothing about the knees).  dropout: probability, per hand,
    of a 0.1-0.5 s tracking gap in the input, bridged as the resampler
    bridges real gaps (linear / slerp) or frozen at the last pose.  lying:
    probability that the window's whole body is laid down on the floor
    (:meth:`WindowSampler._lay_down`: on the back, the front or a side, as
    people lie on the floor; the source motion's limbs keep moving), where its
    limbs let it lie flat (about half the Bandai windows do).  crouch:
    probability that the window crouches (:meth:`WindowSampler._crouch`: the
    pelvis sinks and the legs fold onto the planted feet).  stoop:
    probability that the window bends over at the hips (:meth:`WindowSampler._stoop`:
    a reach to the floor, a look under a table).  stoop_knees: how far a
    stooping window's knees may bend, as the largest share of each leg's
    hip-to-ankle reach they take off (uniform per window from 0): 0.03 keeps
    the legs nearly straight (up to about 25°), 0.45 also gives the
    semi-squat people mostly lift with (up to about 110°).  stoop_bend:
    (low, high) degrees, the range a stoop's trunk bends forward by (uniform
    per window); past 90° the head goes below the hips, as in a full
    forward fold.  stoop_look: the largest share of a stoop's bend the neck
    and head take back (uniform per window from 0), as people who bend over
    keep looking at what they reach for; 0 turns the head with the trunk.
    """
    speed: tuple = (0.8, 1.25)
    stature: tuple | None = (1.45, 2.05)
    segment: float = 0.12
    floor: float = 0.03
    mirror: float = 0.5
    pos_noise: float = 0.004
    rot_noise_deg: float = 2.0
    hand_offset_deg: float = 5.0
    head_offset: float = 0.02
    edge_prob: float = 0.05
    calibration: float = 0.1
    arm_mix: float = 0.3
    dropout: float = 0.1
    lying: float = 0.0
    crouch: float = 0.0
    stoop: float = 0.0
    stoop_knees: float = 0.03
    stoop_bend: tuple = (25.0, 95.0)
    stoop_look: float = 0.0

    def check(self):
        """Raise ``ValueError`` for a setting the sampler cannot use."""
        if not 0.0 <= float(self.stoop_knees) <= STOOP_MAX_KNEES:
            raise ValueError(f"stoop_knees {self.stoop_knees!r}: must be between 0 and {STOOP_MAX_KNEES} "
                             f"(a share of the leg's hip-to-ankle reach)")
        low, high = (float(v) for v in self.stoop_bend)
        if not 0.0 <= low <= high <= STOOP_MAX_BEND:
            raise ValueError(f"stoop_bend {low:g},{high:g}: must be LOW,HIGH degrees with "
                             f"0 <= LOW <= HIGH <= {STOOP_MAX_BEND:g}")
        if not 0.0 <= float(self.stoop_look) <= 1.0:
            raise ValueError(f"stoop_look {self.stoop_look!r}: must be between 0 and 1 (a share of the bend)")

    @classmethod
    def off(cls):
        return cls(speed=(1.0, 1.0), stature=None, segment=0.0, floor=0.0, mirror=0.0, pos_noise=0.0,
                   rot_noise_deg=0.0, hand_offset_deg=0.0, head_offset=0.0, edge_prob=0.0, calibration=0.0,
                   arm_mix=0.0, dropout=0.0, lying=0.0, crouch=0.0, stoop=0.0)


@dataclass
class ClipSet:
    """Clips concatenated in memory."""
    quat: np.ndarray          # (N, 22, 4) float32
    root_pos: np.ndarray      # (N, 3)
    contacts: np.ndarray      # (N, 2) uint8
    starts: np.ndarray        # (C,) first frame of each clip
    lengths: np.ndarray       # (C,)
    offsets: np.ndarray       # (C, 22, 3) float64
    stature: np.ndarray       # (C,)
    names: list = field(default_factory=list)
    lowest: np.ndarray = None  # (C,) 1st percentile of the lowest foot joint's height, metres

    @classmethod
    def load(cls, files):
        if not files:
            raise ValueError("no clip files")
        q, rp, ct, lens, offs, st, names = [], [], [], [], [], [], []
        for f in files:
            with np.load(f) as z:
                q.append(z["local_quat"])
                rp.append(z["root_pos"])
                ct.append(z["contacts"])
                lens.append(z["local_quat"].shape[0])
                offs.append(z["offsets"].astype(np.float64))
                st.append(float(z["stature"]))
                names.append(str(z["name"]))
        lens = np.array(lens, np.int64)
        out = cls(np.concatenate(q), np.concatenate(rp), np.concatenate(ct),
                  np.concatenate([[0], np.cumsum(lens)[:-1]]).astype(np.int64), lens,
                  np.stack(offs), np.array(st), names)
        out.lowest = out.lowest_foot_heights()
        return out

    def lowest_foot_heights(self, chunk=65536):
        """``(C,)`` per clip: the 1st percentile over frames of the lowest ankle or ball height
        (metres), where the clip stands on its floor."""
        zmin = np.empty(self.quat.shape[0])
        cid = np.repeat(np.arange(len(self.lengths)), self.lengths)
        for a in range(0, zmin.shape[0], chunk):
            b = min(a + chunk, zmin.shape[0])
            R = rot.quat_to_matrix(self.quat[a:b].astype(np.float64))
            P, _ = forward_kinematics(R, self.root_pos[a:b].astype(np.float64), None,
                                      offsets=self.offsets[cid[a:b]])
            zmin[a:b] = P[:, _FOOT_JOINTS, 2].min(-1)
        return np.array([np.percentile(zmin[s:s + n], 1.0) for s, n in zip(self.starts, self.lengths)])

    @property
    def frames(self):
        return int(self.lengths.sum())


#: offsets each segment-group factor scales: (joint, axes) pairs
SEGMENT_GROUPS = {
    "feet": [(J["left_foot"], (0, 1, 2)), (J["right_foot"], (0, 1, 2))],
    "thigh": [(J["left_knee"], (0, 1, 2)), (J["right_knee"], (0, 1, 2))],
    "shank": [(J["left_ankle"], (0, 1, 2)), (J["right_ankle"], (0, 1, 2))],
    "torso": [(J[n], (0, 1, 2)) for n in ("spine1", "spine2", "spine3", "neck")]
             + [(J["left_collar"], (2,)), (J["right_collar"], (2,))],
    "head": [(J["head"], (0, 1, 2))],
    "arms": [(J[n], (0, 1, 2)) for n in ("left_elbow", "right_elbow", "left_wrist", "right_wrist")],
    "shoulders": [(J[n], (0,)) for n in ("left_collar", "right_collar", "left_shoulder", "right_shoulder")],
    "hips": [(J["left_hip"], (0,)), (J["right_hip"], (0,))],
}
#: which body measure (features.BODY_FEATURES index) each group's factor moves
GROUP_MEASURE = {"thigh": (0,), "shank": (1,), "feet": (2,), "torso": (3,), "head": (4,), "hips": (5,),
                 "shoulders": (6,), "arms": (7, 8)}
_FOOT_JOINTS = [J["left_ankle"], J["right_ankle"], J["left_foot"], J["right_foot"]]
_LEG_CHAINS = [(J["left_hip"], J["left_knee"], J["left_ankle"], J["left_foot"]),
               (J["right_hip"], J["right_knee"], J["right_ankle"], J["right_foot"])]


def lowest_foot_height(local, root, offsets):
    """``(N,)`` height of the lowest ankle or ball joint: FK of the two leg chains only.

    local ``(N, 22, 3, 3)``, root ``(N, 3)``, offsets ``(N, 22, 3)``."""
    R0 = local[:, 0]
    low = None
    for chain in _LEG_CHAINS:
        p, R = root, R0
        for j in chain:
            p = p + np.einsum("nij,nj->ni", R, offsets[:, j])
            R = R @ local[:, j]
            if j in _FOOT_JOINTS:
                low = p[:, 2] if low is None else np.minimum(low, p[:, 2])
    return low


#: the body measures (:data:`features.BODY_FEATURES`, in the network's statures) of the body the
#: solver builds by default (:func:`~..core.skeleton.make_body`), that random bodies move towards
_DEFAULT_OFFSETS = make_body(1.0).offsets
SOLVER_MEASURES = features.body_measures(_DEFAULT_OFFSETS, features.stature_from_offsets(_DEFAULT_OFFSETS))
#: the network's statures (:func:`features.stature_from_offsets`) between the soles and the
#: lowest foot joint of a standing foot: make_body's ball of the foot, foot_height of the body
#: model's stature, which is 0.871 / 0.831 network statures; the soles (:data:`SOLE` metres)
#: lift it further, as make_body does
FOOT_CLEARANCE = PROPORTIONS["foot_height"] / float(features.stature_from_offsets(_DEFAULT_OFFSETS))


def mirror_motion(local, root, offsets, contacts):
    """Left/right mirror image (x -> -x) of a motion.

    local ``(..., 22, 3, 3)`` local rotations, root ``(..., 3)``, offsets
    ``(..., 22, 3)``, contacts ``(..., 2)``.  Every rest frame is world
    aligned, so the mirrored rotation of joint j is ``M R[mirror(j)] M`` with
    ``M = diag(-1, 1, 1)`` (a proper rotation); left and right hinge axes of
    the limb solver are mirror images, so hinges stay hinges."""
    M = MIRROR_M
    local_m = M @ local[..., MIRROR_JOINTS, :, :] @ M
    root_m = root * np.array([-1.0, 1.0, 1.0])
    offsets_m = offsets[..., MIRROR_JOINTS, :] * np.array([-1.0, 1.0, 1.0])
    return local_m, root_m, offsets_m, contacts[..., ::-1]


def calibration_pose(rng, B):
    """``(B, 22, 4)`` local quaternions of standing calibration poses: half
    T-poses (arms 8° below to 12° above horizontal), half A-poses (arms 30-50°
    down), elbows bent 0-12°, head pitched ±15°, legs straight (hips ±4°
    apart, knees 0-4°).  Root rotation identity (upright, facing -Y)."""
    aa = np.zeros((B, NUM_JOINTS, 3))
    a_pose = rng.uniform(size=B) < 0.5
    down = np.where(a_pose, rng.uniform(np.radians(30), np.radians(50), B),
                    rng.uniform(np.radians(-12), np.radians(8), B))
    aa[:, J["left_shoulder"], 1] = down + rng.normal(0, np.radians(3), B)
    aa[:, J["right_shoulder"], 1] = -(down + rng.normal(0, np.radians(3), B))
    for li, (_, _, m, _) in enumerate(LIMBS):
        top = np.radians(12.0) if li < 2 else np.radians(4.0)
        aa[:, m] = ls.H0[li] * rng.uniform(0.0, top, B)[:, None]
    aa[:, J["head"], 0] = rng.uniform(-np.radians(15), np.radians(15), B)
    spread = rng.uniform(0.0, np.radians(4), B)
    aa[:, J["left_hip"], 1] = -spread
    aa[:, J["right_hip"], 1] = spread
    return rot.matrix_to_quat(rot.axis_angle_to_matrix(aa))


#: a body lying on the floor (``Augment.lying``): its trunk joints' lowest point this many statures
#: up (the joint centres of a supine adult's pelvis and back are 8-11 cm above the floor), and no
#: joint lower than LYING_CLEARANCE statures (a heel or wrist on the floor)
LYING_TRUNK_CLEARANCE = 0.055
LYING_CLEARANCE = 0.02
#: statures a lying body's limbs may prop its trunk above the floor (else the window stays upright)
LYING_MAX_PROP = 0.05
#: ways of lying down tried per window (on the back, the front and either side)
LYING_TRIES = 4
#: the trunk joints a lying body rests on
LYING_TRUNK = np.array([J[n] for n in ("pelvis", "spine1", "spine2", "spine3", "neck", "head", "left_hip", "right_hip",
                                      "left_collar", "right_collar", "left_shoulder", "right_shoulder")])
#: how far a crouching window's pelvis sinks, statures (uniform; a deep squat sinks ~0.3)
CROUCH_DEPTH = (0.08, 0.32)
#: forward lean of a crouching trunk, radians per stature of depth (0.3 statures: ~20°)
CROUCH_LEAN = 1.2
#: the most a stooping trunk may bend forward, degrees (``Augment.stoop_bend``: by default 25-95°,
#: uniform; a reach to the floor with straight legs bends it about 90°, a full fold further)
STOOP_MAX_BEND = 150.0
#: the share of a stoop's bend taken at the hips (the pelvis pitches); the rest is spread evenly
#: over the three spine joints
STOOP_HIP_SHARE = (0.5, 0.8)
#: how far a stooping pelvis moves back to keep the balance, statures times sin(bend)
STOOP_BACK = 0.08
#: the largest a stooping leg's hip-to-ankle distance may shrink by, as a share of what it was
#: (``Augment.stoop_knees`` picks the upper end of the uniform draw per window, at most this)
STOOP_MAX_KNEES = 0.6
#: the legs' limb ids (``LIMBS`` order) and their hip, knee and ankle joints
LEGS = [2, 3]
LEG_HIPS = [LIMBS[i][1] for i in LEGS]
LEG_KNEES = [LIMBS[i][2] for i in LEGS]
LEG_ANKLES = [LIMBS[i][3] for i in LEGS]
SPINE = [J["spine1"], J["spine2"], J["spine3"]]


#: the joints whose local rotations the arm mix exchanges (collars down to the wrists)
ARM_JOINTS = np.array([J[f"{s}_{n}"] for s in ("left", "right") for n in ("collar", "shoulder", "elbow", "wrist")])


def tracking_gaps(rng, pos, R, prob, fps, seconds=(0.1, 0.5)):
    """Inputs ``pos (B, W, 3)``, ``R (B, W, 3, 3)`` with, in a ``prob`` share of the windows, one
    tracking gap of ``seconds`` bridged linearly (slerp for the orientation) like the resampler
    bridges lost samples, or frozen at the last pose before it (half each)."""
    B, W = pos.shape[:2]
    pos, R = pos.copy(), R.copy()
    for b in np.nonzero(rng.uniform(size=B) < prob)[0]:
        n = int(np.clip(round(rng.uniform(*seconds) * fps), 1, W - 2))
        g0 = int(rng.integers(1, W - n))
        g1 = g0 + n                                   # first frame after the gap (< W)
        if rng.uniform() < 0.5:
            w = (np.arange(1, n + 1) / (n + 1))[:, None]
            pos[b, g0:g1] = pos[b, g0 - 1] * (1 - w) + pos[b, g1] * w
            q0, q1 = rot.matrix_to_quat(R[b, g0 - 1]), rot.matrix_to_quat(R[b, g1])
            R[b, g0:g1] = rot.quat_to_matrix(rot.quat_slerp(np.broadcast_to(q0, (n, 4)), np.broadcast_to(q1, (n, 4)),
                                                            w[:, 0]))
        else:
            pos[b, g0:g1] = pos[b, g0 - 1]
            R[b, g0:g1] = R[b, g0 - 1]
    return pos, R


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _hold_weights(W, start, hold, ramp):
    """``(n, W)`` weights of a hold: 1 over frames ``[start, start + hold]``, eased in and out
    by a smoothstep over ``ramp`` frames on either side, 0 elsewhere.  start, hold ``(n,)``
    frames; ramp a scalar or ``(n,)`` frames."""
    t = np.arange(W)[None]
    start, hold = np.asarray(start)[:, None], np.asarray(hold)[:, None]
    ramp = np.broadcast_to(np.asarray(ramp, np.float64), start.shape[:1])[:, None]
    return _smoothstep((t - start + ramp) / ramp) * _smoothstep((start + hold + ramp - t) / ramp)


def _small_rotations(rng, shape, sigma_rad):
    """Random rotation matrices with per-axis N(0, sigma/sqrt(3)) (rms angle sigma)."""
    return rot.axis_angle_to_matrix(rng.normal(size=shape + (3,)) * (sigma_rad / math.sqrt(3.0)))


def _window_fk(local, root, offsets):
    """FK of windows: ``(positions (n, W, 22, 3), world rotations (n, W, 22, 3, 3))`` of local
    rotations ``(n, W, 22, 3, 3)``, root ``(n, W, 3)`` and each window's offsets ``(n, 22, 3)``."""
    n, W = root.shape[:2]
    P, R = forward_kinematics(local.reshape(n * W, NUM_JOINTS, 3, 3), root.reshape(n * W, 3), None,
                              offsets=np.repeat(offsets, W, 0))
    return P.reshape(n, W, NUM_JOINTS, 3), R.reshape(n, W, NUM_JOINTS, 3, 3)


def _leg_lengths(offsets):
    """``(n, 2, 2)`` thigh and shank lengths of both legs, from offsets ``(n, 22, 3)``."""
    return np.stack([np.linalg.norm(offsets[:, LEG_KNEES], axis=-1),
                     np.linalg.norm(offsets[:, LEG_ANKLES], axis=-1)], -1)


def _replant_legs(loc, root, P, Rw, offsets):
    """The legs of a moved trunk solved again onto the ankles where they were.

    loc ``(n, W, 22, 3, 3)`` local rotations and root ``(n, W, 3)`` metres of the new motion (the
    trunk moved, the legs as before); P ``(n, W, 22, 3)`` and Rw ``(n, W, 22, 3, 3)``: the FK of
    the motion before; offsets ``(n, 22, 3)``.  Each knee keeps its swivel, each ankle its world
    orientation (:func:`.limb_solver.solve_limbs`: hinge knees).  Returns ``loc`` with new hip,
    knee and ankle rotations (changed in place)."""
    n, W = root.shape[:2]
    swivel = ls.swivel_from_positions(P[:, :, LEG_HIPS], P[:, :, LEG_KNEES], P[:, :, LEG_ANKLES], Rw[:, :, [0, 0]],
                                      LEGS, base_rot=Rw[:, :, LEG_HIPS])
    P2, Rw2 = _window_fk(loc, root, offsets)
    lengths = np.broadcast_to(_leg_lengths(offsets)[:, None], (n, W, 2, 2))
    sol = ls.solve_limbs(P2[:, :, LEG_HIPS], P[:, :, LEG_ANKLES], swivel, lengths, Rw2[:, :, [0, 0]],
                         end_rot=Rw[:, :, LEG_ANKLES], limb_ids=LEGS)
    loc[:, :, LEG_HIPS] = sol.base_local
    loc[:, :, LEG_KNEES] = sol.mid_local
    loc[:, :, LEG_ANKLES] = sol.end_local
    return loc


def _turn_about_world_axis(loc, Rw, joints, axis, angle):
    """Turn each of ``joints`` by ``angle`` ``(n, W)`` radians about the world ``axis`` ``(n, W, 3)``,
    in place in the local rotations ``loc`` ``(n, W, 22, 3, 3)``.  ``Rw`` ``(n, W, 22, 3, 3)`` are
    the world rotations before any of these turns: each joint's turn is expressed in its parent's
    frame as it was, which holds while every turn added above it is about the same world axis."""
    for j in joints:
        local_axis = np.einsum("nwji,nwj->nwi", Rw[:, :, PARENTS[j]], axis)
        loc[:, :, j] = rot.axis_angle_to_matrix(local_axis * angle[..., None]) @ loc[:, :, j]


def _facing_axes(R0):
    """``(side, back)``: the horizontal left (+X) and back (+Y) unit axes of pelvis rotations
    ``(..., 3, 3)``, each ``(..., 3)``."""
    side = R0[..., :, 0].copy()
    side[..., 2] = 0.0
    side = rot.normalize(side)
    return side, np.cross(np.broadcast_to([0.0, 0.0, 1.0], side.shape), side)


class WindowSampler:
    """Random training windows as numpy batches.

    ``sample(B)`` returns a dict of float32 arrays:

    * ``x`` ``(B, W, 12 D)`` network input (:func:`features.make_inputs`);
    * ``y`` ``(B, W, F_out)`` targets (:func:`features.encode_targets`, ``kind``);
    * ``pos`` ``(B, W, 22, 3)`` ground-truth joint positions in the canonical
      frame, in statures; ``offsets`` ``(B, 22, 3)`` rest offsets in statures;
      ``stature`` ``(B,)`` metres (after the scale augmentation).
    """

    def __init__(self, clips, window=40, kind="manikin", devices=features.INPUT_DEVICES,
                 augment=None, seed=0, fps=MODEL_FPS, body=True, balance=0.0):
        self.clips = clips if isinstance(clips, ClipSet) else ClipSet.load(list(clips))
        self.window = int(window)
        self.kind = kind
        self.devices = tuple(devices)
        self.body = bool(body)
        self.aug = Augment() if augment is None else augment
        self.aug.check()
        self.fps = float(fps)
        self.rng = np.random.default_rng(seed)
        self.p = self.clip_probabilities(balance)
        self.balance = float(balance)

    def clip_probabilities(self, balance=0.0):
        """``(C,)`` float64: the probability that a window is drawn from each clip.

        balance: 0 draws every frame alike (a clip in proportion to its length); ``b`` in (0, 1]
        divides each clip's length by its group's total frames to the power ``b``
        (:func:`motion_group`: the motion class in the take's name), so a group's share of the
        windows goes as its frames to the power ``1 - b``: at 0.5, a class with a hundredth of
        another's frames gets a tenth of its windows; at 1, every group gets the same share.
        Rare classes (kicks, dance) are then seen more often without dropping any frame."""
        b = float(balance)
        if not 0.0 <= b <= 1.0:
            raise ValueError(f"balance {balance!r}: expected a number from 0 to 1")
        w = self.clips.lengths.astype(np.float64)
        if b > 0.0:
            if len(self.clips.names) != len(w):
                raise ValueError("balance needs the clips' take names (ClipSet.names)")
            groups = [motion_group(n) for n in self.clips.names]
            total = {}
            for g, n in zip(groups, w):
                total[g] = total.get(g, 0.0) + n
            w = w * np.array([total[g] for g in groups]) ** -b
        return w / w.sum()

    def group_shares(self):
        """``{group: share}``: each sampling group's (:func:`motion_group`) share of the windows
        drawn, largest first."""
        shares = {}
        for name, p in zip(self.clips.names, self.p):
            g = motion_group(name)
            shares[g] = shares.get(g, 0.0) + float(p)
        return dict(sorted(shares.items(), key=lambda kv: -kv[1]))

    # rng state, for exact resume
    def get_state(self):
        return self.rng.bit_generator.state

    def set_state(self, state):
        self.rng.bit_generator.state = state

    def batch_for_step(self, step, B, seed=0):
        """The batch of training step ``step``: a pure function of ``(seed, step)``,
        so batches can be made ahead in another process and a resumed run
        sees exactly the batches an uninterrupted one would."""
        return self.sample(B, np.random.default_rng([int(seed), int(step)]))

    def _times(self, B, rng):
        """Clip ids ``(B,)`` and fractional frame times ``(B, W)`` within each clip."""
        W, a = self.window, self.aug
        cid = rng.choice(len(self.p), size=B, p=self.p)
        lo, hi = np.log(a.speed[0]), np.log(a.speed[1])
        f = np.exp(rng.uniform(lo, hi, B)) if hi > lo else np.full(B, a.speed[0])
        L = self.clips.lengths[cid].astype(np.float64)
        span = (W - 1) * f
        room = np.maximum(L - 1 - span, 0.0)
        start = rng.uniform(0.0, 1.0, B) * room
        if hi <= lo and a.speed[0] == 1.0:
            start = np.floor(start)
        t = start[:, None] + np.arange(W)[None] * f[:, None]
        if a.edge_prob > 0:
            edge = rng.uniform(size=B) < a.edge_prob
            shift = rng.uniform(-W / 2, W / 2, B)
            t = np.where(edge[:, None], t + shift[:, None], t)
        return cid, np.clip(t, 0.0, L[:, None] - 1)

    def _random_body(self, rng, offsets):
        """A new body for each window: ``(offsets (B, 22, 3), stature (B,), k (B,))``.

        Every segment group is scaled by its own factor (see :class:`Augment`), then the whole
        body so the stature lands in ``Augment.stature``.  The stature is the network's length
        unit (:func:`features.stature_from_offsets`: the head joint above the ankles standing
        straight / 0.871), whatever the source skeleton's floor convention.  ``k``: new
        stature / the source body's stature."""
        a, B = self.aug, offsets.shape[0]
        s0 = features.stature_from_offsets(offsets)
        out = offsets.copy()
        if a.segment > 0:
            lo, hi = np.log(1 - a.segment), np.log(1 + a.segment)
            # Each group moves a random part of the way from the source skeleton's proportion to
            # the solver's default body's, then by up to ±segment: so the training bodies span
            # both, and every body the solver builds is inside that range.
            to_ref = np.log(SOLVER_MEASURES / features.body_measures(offsets, s0))             # (B, K)
            g = {}
            for name, idx in GROUP_MEASURE.items():
                r = to_ref[:, list(idx)].mean(-1)
                g[name] = np.exp(rng.uniform(0.0, 1.3, B) * r + rng.uniform(lo, hi, B))
            legs = np.exp(rng.uniform(lo, hi, B))      # both leg segments together as well
            g["thigh"] = g["thigh"] * legs
            g["shank"] = g["shank"] * legs
            for name, members in SEGMENT_GROUPS.items():
                for j, axes in members:
                    out[:, j, list(axes)] *= g[name][:, None]
        s1 = features.stature_from_offsets(out)
        if a.stature is not None:
            target = rng.uniform(a.stature[0], a.stature[1], B)
            out *= (target / s1)[:, None, None]
            s1 = target
        return out, s1, s1 / s0

    def _blend_calibration(self, rng, q, root, contacts, offsets, lowest):
        """Blend a held calibration pose (0.5-2 s, 0.3 s ramps) into some windows, as real
        recordings begin: the body turns to the motion's heading, stands on the clip's floor
        with both feet planted."""
        a, (B, W) = self.aug, q.shape[:2]
        pick = np.nonzero(rng.uniform(size=B) < a.calibration)[0]
        if pick.size == 0:
            return q, root, contacts
        n = pick.size
        pose = calibration_pose(rng, n)                                       # (n, 22, 4)
        yaw = features.heading_yaw(rot.quat_to_matrix(q[pick, W // 2, 0]))
        pose[:, 0] = rot.matrix_to_quat(features.rot_z(yaw))
        P, _ = forward_kinematics(rot.quat_to_matrix(pose), np.zeros((n, 3)), None, offsets=offsets[pick])
        stand = np.empty((n, 3))
        stand[:, :2] = root[pick, W // 2, :2]
        stand[:, 2] = lowest[pick] - P[:, _FOOT_JOINTS, 2].min(-1)
        hold = rng.uniform(0.5, 2.0, n) * self.fps
        ramp = 0.3 * self.fps
        start = rng.uniform(-hold, W, n)
        wgt = _hold_weights(W, start, hold, ramp)
        q, root, contacts = q.copy(), root.copy(), contacts.copy()
        q[pick] = rot.quat_slerp(q[pick], np.broadcast_to(pose[:, None], q[pick].shape), wgt[..., None])
        root[pick] = root[pick] * (1 - wgt[..., None]) + stand[:, None] * wgt[..., None]
        contacts[pick] = np.where(wgt[..., None] > 0.5, 1.0, contacts[pick])
        return q, root, contacts

    def _random_hold(self, rng, n, W):
        """``(n, W)`` weights of one random hold per window (:func:`_hold_weights`): held
        0.5-2 s, eased in and out over 0.3-0.8 s, starting anywhere that overlaps the window."""
        hold = rng.uniform(0.5, 2.0, n) * self.fps
        ramp = rng.uniform(0.3, 0.8, n) * self.fps
        start = rng.uniform(-hold, W, n)
        return _hold_weights(W, start, hold, ramp)

    def _crouch(self, rng, local, root, offsets, stature):
        """Crouch a share (``Augment.crouch``) of the windows: the pelvis sinks by up to
        :data:`CROUCH_DEPTH` statures (held 0.5-2 s, eased in and out over 0.3-0.8 s) and a
        quarter of that back, the trunk leans forward with it (:data:`CROUCH_LEAN` radians per
        stature of depth), and the legs are solved again (:func:`.limb_solver.solve_limbs`)
        onto the feet where they were, each knee keeping its swivel: a squat, a duck under a
        wall, a reach to the floor, with the feet planted as before.  The arms and head move with
        the trunk.  The Bandai takes hold few deep crouches, and a network that has not seen
        them takes a low head for a body lying down.

        local ``(B, W, 22, 3, 3)``, root ``(B, W, 3)`` metres, offsets ``(B, 22, 3)``, stature
        ``(B,)``.  Returns new ``(local, root)``."""
        B, W = root.shape[:2]
        pick = np.nonzero(rng.uniform(size=B) < self.aug.crouch)[0]
        if pick.size == 0:
            return local, root
        n = pick.size
        s = stature[pick]
        depth = rng.uniform(CROUCH_DEPTH[0], CROUCH_DEPTH[1], n) * s
        wgt = self._random_hold(rng, n, W)
        d = depth[:, None] * wgt                                                          # (n, W)
        loc = local[pick].copy()
        rt = root[pick].copy()
        off = offsets[pick]
        P, Rw = _window_fk(loc, rt, off)
        R0 = loc[:, :, 0]
        side, back = _facing_axes(R0)
        lean = CROUCH_LEAN * d / s[:, None]
        loc[:, :, 0] = rot.axis_angle_to_matrix(side * lean[..., None]) @ R0
        rt = rt - d[..., None] * np.array([0.0, 0.0, 1.0]) + 0.25 * d[..., None] * back
        loc = _replant_legs(loc, rt, P, Rw, off)
        local, root = local.copy(), root.copy()
        local[pick], root[pick] = loc, rt
        return local, root

    def _stoop(self, rng, local, root, offsets, stature):
        """Bend a share (``Augment.stoop``) of the windows over at the hips: the trunk pitches
        forward by ``Augment.stoop_bend`` (held 0.5-2 s, eased in and out over 0.3-0.8 s), a share
        :data:`STOOP_HIP_SHARE` of it at the hips and the rest through the spine, the pelvis
        moves back (:data:`STOOP_BACK`) and down as far as the legs need to keep their reach less
        a random share of it up to ``Augment.stoop_knees`` (the knees straight, softened or
        bent into a semi-squat), and the legs are solved again onto
        the feet where they were.  The arms move with the trunk; the head does too, less a
        random share of the bend up to ``Augment.stoop_look`` that the neck and head take back
        (looking at what the hands reach for).  A head low and ahead,
        pitched down, is then a body bent over as often as a crouch (:meth:`_crouch`), as people
        reach for the floor both ways; the Bandai takes hold few of either.

        local ``(B, W, 22, 3, 3)``, root ``(B, W, 3)`` metres, offsets ``(B, 22, 3)``, stature
        ``(B,)``.  Returns new ``(local, root)``."""
        B, W = root.shape[:2]
        pick = np.nonzero(rng.uniform(size=B) < self.aug.stoop)[0]
        if pick.size == 0:
            return local, root
        n = pick.size
        s = stature[pick]
        bend = np.radians(rng.uniform(self.aug.stoop_bend[0], self.aug.stoop_bend[1], n))
        share = rng.uniform(STOOP_HIP_SHARE[0], STOOP_HIP_SHARE[1], n)
        wgt = self._random_hold(rng, n, W)                                                 # (n, W)
        loc = local[pick].copy()
        rt = root[pick].copy()
        off = offsets[pick]
        P, Rw = _window_fk(loc, rt, off)
        side, back = _facing_axes(loc[:, :, 0])
        loc[:, :, 0] = rot.axis_angle_to_matrix(side * ((bend * share)[:, None] * wgt)[..., None]) @ loc[:, :, 0]
        _turn_about_world_axis(loc, Rw, SPINE, side, (bend * (1.0 - share) / len(SPINE))[:, None] * wgt)
        if self.aug.stoop_look > 0:
            # the neck and head take part of the bend back, half each
            look = -(bend * rng.uniform(0.0, self.aug.stoop_look, n) / 2.0)[:, None] * wgt
            _turn_about_world_axis(loc, Rw, (J["neck"], J["head"]), side, look)
        rt = rt + (STOOP_BACK * s * np.sin(bend))[:, None, None] * wgt[..., None] * back
        # lower the pelvis where the bend lifts the hips further from the feet than they were,
        # the knees bending by up to Augment.stoop_knees of the leg's reach (Newton steps on the
        # hip-to-ankle distance against the pelvis' height; only legs that hang down from the
        # hip, where lowering it brings the foot closer: a foot kicked up to the hip is left be)
        soft = rng.uniform(0.0, self.aug.stoop_knees, n)[:, None] * wgt                   # (n, W)
        reach = np.linalg.norm(P[:, :, LEG_HIPS] - P[:, :, LEG_ANKLES], axis=-1) * (1.0 - soft)[..., None]
        for _ in range(4):
            leg = _window_fk(loc, rt, off)[0][:, :, LEG_HIPS] - P[:, :, LEG_ANKLES]           # (n, W, 2, 3)
            gap = np.linalg.norm(leg, axis=-1)
            down = leg[..., 2] > 0.3 * gap
            step = np.maximum(gap - reach, 0.0) * gap / np.where(down, leg[..., 2], 1.0)
            rt[..., 2] -= np.where(down, step, 0.0).max(-1)
        loc = _replant_legs(loc, rt, P, Rw, off)
        local, root = local.copy(), root.copy()
        local[pick], root[pick] = loc, rt
        return local, root

    def _lay_down(self, rng, local, root, contacts, offsets, stature):
        """Lay the whole body of a share (``Augment.lying``) of the windows down on the floor.

        The body turns about a horizontal axis by 84-96° (on its back, its front or a side,
        depending on the axis against its heading: of :data:`LYING_TRIES` axes a quarter turn
        apart from a random start, the one whose limbs prop the trunk least), drifting by up to ±6°
        over the window; its horizontal path is the source motion's turned the same way and
        projected on the floor (a walking window lies in place, kicking), and on every frame
        it rests on the floor: the lowest trunk joint (pelvis, spine, neck, head, hips,
        collars, shoulders) :data:`LYING_TRUNK_CLEARANCE` statures up, no joint below
        :data:`LYING_CLEARANCE` statures.  A window whose limbs would prop the trunk more than
        :data:`LYING_MAX_PROP` statures off the floor stays upright.  The contacts are measured
        again on the new motion (:func:`foot_contacts`).  Real recordings have this when a player
        lies down or rolls on the floor; the Bandai takes have no floor work.

        local ``(B, W, 22, 3, 3)``, root ``(B, W, 3)`` metres, contacts ``(B, W, 2)``, offsets
        ``(B, 22, 3)`` metres, stature ``(B,)`` metres.  Returns new ``(local, root, contacts)``.
        """
        B, W = root.shape[:2]
        pick = np.nonzero(rng.uniform(size=B) < self.aug.lying)[0]
        if pick.size == 0:
            return local, root, contacts
        n, K = pick.size, LYING_TRIES
        # K ways to lie down per window (axes a quarter turn apart, from a random start); the one
        # whose limbs prop the trunk least is kept
        yaw = rng.uniform(0.0, 2.0 * np.pi, n)[:, None] + 0.5 * np.pi * np.arange(K)[None]    # (n, K)
        axis = np.stack([np.cos(yaw), np.sin(yaw), np.zeros((n, K))], -1).reshape(n * K, 3)
        tilt = np.repeat(rng.uniform(np.radians(84.0), np.radians(96.0), n), K)
        drift = np.repeat(rng.uniform(-np.radians(6.0), np.radians(6.0), n), K)
        angle = tilt[:, None] + drift[:, None] * (np.arange(W) / max(W - 1, 1) - 0.5)[None]   # (nK, W)
        G = rot.axis_angle_to_matrix(axis[:, None] * angle[..., None])                     # (nK, W, 3, 3)
        src = np.repeat(pick, K)
        lp = local[src]
        lp[:, :, 0] = G @ lp[:, :, 0]
        c = root[src, W // 2][:, None]
        moved = np.einsum("nwij,nwj->nwi", G, root[src] - c) + c
        rp = np.concatenate([moved[..., :2], np.zeros((n * K, W, 1))], -1)
        P = _window_fk(lp, rp, offsets[src])[0]
        s = stature[src][:, None]
        trunk = LYING_TRUNK_CLEARANCE * s - P[:, :, LYING_TRUNK, 2].min(-1)               # (nK, W)
        lift = np.maximum(trunk, LYING_CLEARANCE * s - P[..., 2].min(-1))
        # a window whose limbs would hold the trunk up off the floor (arms reaching forward with
        # the body face down) is not laid down that way: such a body would float, and its head
        # would be as low as a crouching performer's
        prop = ((lift - trunk).max(-1) / s[:, 0]).reshape(n, K)
        best = prop.argmin(-1)
        keep = prop[np.arange(n), best] <= LYING_MAX_PROP
        sel = (np.arange(n) * K + best)[keep]
        pick, lp, rp, P, lift = pick[keep], lp[sel], rp[sel], P[sel], lift[sel]
        local, root, contacts = local.copy(), root.copy(), contacts.copy()
        rp[..., 2] = lift
        P[..., 2] += lift[..., None]
        local[pick], root[pick] = lp, rp
        for i, b in enumerate(pick):
            contacts[b] = foot_contacts(P[i], self.fps)
        return local, root, contacts

    def sample(self, B, rng=None):
        rng = self.rng if rng is None else rng
        W, a, cs = self.window, self.aug, self.clips
        cid, t = self._times(B, rng)
        base = cs.starts[cid][:, None]
        i0 = np.floor(t).astype(np.int64)
        i1 = np.minimum(i0 + 1, cs.lengths[cid][:, None] - 1)
        w = t - i0
        q0 = cs.quat[base + i0].astype(np.float64)
        if np.any(w > 0):
            q1 = cs.quat[base + i1].astype(np.float64)
            q = rot.quat_slerp(q0, q1, np.broadcast_to(w[..., None], q0.shape[:-1]))
        else:
            q = q0
        root = (cs.root_pos[base + i0] * (1 - w)[..., None] + cs.root_pos[base + i1] * w[..., None]).astype(np.float64)
        contacts = cs.contacts[base + np.rint(t).astype(np.int64)].astype(np.float64)
        offsets = cs.offsets[cid].copy()                                      # (B, 22, 3)
        lowest = cs.lowest[cid] if cs.lowest is not None else np.zeros(B)

        if a.calibration > 0:
            q, root, contacts = self._blend_calibration(rng, q, root, contacts, offsets, lowest)
        if a.arm_mix > 0 and B > 1:
            mix = np.nonzero(rng.uniform(size=B) < a.arm_mix)[0]
            if mix.size:
                donor = (mix + rng.integers(1, B, mix.size)) % B          # another window of the batch
                q = q.copy()
                frames = np.arange(W)
                q[np.ix_(mix, frames, ARM_JOINTS)] = q[np.ix_(donor, frames, ARM_JOINTS)]
        local = rot.quat_to_matrix(q)                                         # (B, W, 22, 3, 3)
        if a.mirror > 0:
            flip = rng.uniform(size=B) < a.mirror
            if flip.any():
                lm, rm, om, cm = mirror_motion(local[flip], root[flip], offsets[flip], contacts[flip])
                local[flip], root[flip], offsets[flip], contacts[flip] = lm, rm, om, cm

        # Retarget onto a new body: the same local rotations on scaled segments, the root
        # moved so the lowest foot joint keeps its height above the clip's floor (scaled) on
        # every frame, so standing feet stay on the floor and jumps stay jumps.
        N = B * W
        new_off, stature, k = self._random_body(rng, offsets)
        loc_flat = local.reshape(N, NUM_JOINTS, 3, 3)
        low0 = lowest_foot_height(loc_flat, root.reshape(N, 3), np.repeat(offsets, W, 0)).reshape(B, W)
        above0 = (low0 - lowest[:, None]) * k[:, None]
        root = root * k[:, None, None]
        low1 = lowest_foot_height(loc_flat, root.reshape(N, 3), np.repeat(new_off, W, 0)).reshape(B, W)
        above1 = low1 - lowest[:, None] * k[:, None]
        # The floor: standing feet have their lowest joint (the ball) FOOT_CLEARANCE statures and
        # SOLE metres up, as on the body the solver builds (skeleton.make_body); then the floor
        # augmentation.
        offsets = new_off
        root[..., 2] += above0 - above1 - (lowest * k)[:, None] + (FOOT_CLEARANCE * stature)[:, None] + SOLE
        if a.crouch > 0:
            local, root = self._crouch(rng, local, root, offsets, stature)
            loc_flat = local.reshape(N, NUM_JOINTS, 3, 3)
        if a.stoop > 0:
            local, root = self._stoop(rng, local, root, offsets, stature)
            loc_flat = local.reshape(N, NUM_JOINTS, 3, 3)
        if a.lying > 0:
            local, root, contacts = self._lay_down(rng, local, root, contacts, offsets, stature)
            loc_flat = local.reshape(N, NUM_JOINTS, 3, 3)
        if a.floor > 0:
            root[..., 2] += rng.uniform(-a.floor, a.floor, B)[:, None]
        P, Rw = forward_kinematics(loc_flat, root.reshape(N, 3), None, offsets=np.repeat(offsets, W, 0))
        bases = [b for _, b, _, _ in LIMBS]
        mids = [m for _, _, m, _ in LIMBS]
        ends = [e for _, _, _, e in LIMBS]
        swivel = ls.swivel_from_positions(P[:, bases], P[:, mids], P[:, ends], Rw[:, list(ls.LIMB_PARENT)],
                                          base_rot=Rw[:, bases])
        P = P.reshape(B, W, NUM_JOINTS, 3)
        Rw = Rw.reshape(B, W, NUM_JOINTS, 3, 3)
        swivel = swivel.reshape(B, W, 4)

        pos_in, rot_in = {}, {}
        for dev in self.devices:
            j = features.DEVICE_JOINT[dev]
            p = P[:, :, j].copy()
            R = Rw[:, :, j].copy()
            if a.pos_noise > 0:
                p += rng.normal(scale=a.pos_noise, size=p.shape)
            if a.rot_noise_deg > 0:
                R = R @ _small_rotations(rng, (B, W), math.radians(a.rot_noise_deg))
            if a.hand_offset_deg > 0 and dev in HAND_DEVICES:
                axis = rot.normalize(rng.normal(size=(B, 3)))
                ang = rng.uniform(0.0, math.radians(a.hand_offset_deg), B)
                R = R @ rot.axis_angle_to_matrix(axis * ang[:, None])[:, None]
            if a.head_offset > 0 and dev == "head":
                delta = rng.uniform(-a.head_offset, a.head_offset, (B, 3))
                p = p + np.einsum("bwij,bj->bwi", Rw[:, :, j], delta)
            if a.dropout > 0 and dev in HAND_DEVICES:
                p, R = tracking_gaps(rng, p, R, a.dropout, self.fps)
            pos_in[dev], rot_in[dev] = p, R
        body = features.body_features(offsets, stature) if self.body else None
        x, C, o = features.make_inputs(pos_in, rot_in, stature, self.fps, devices=self.devices, body=body)
        y = features.encode_targets(Rw, local, P, swivel, contacts, C, o, stature, kind=self.kind,
                                    head_anchor=pos_in["head"] if "head" in pos_in else None)
        Ct = np.swapaxes(C, -1, -2)
        pos_can = np.einsum("bij,bwkj->bwki", Ct, P - o[:, None, None]) / stature[:, None, None, None]
        return dict(x=x, y=y, pos=pos_can.astype(np.float32),
                    offsets=(offsets / stature[:, None, None]).astype(np.float32),
                    stature=stature.astype(np.float32))


class Prefetcher:
    """Makes ``sampler.batch_for_step`` batches ahead in one forked process.

    ``get(step)`` must be called with consecutive steps.  With ``workers=0``
    (or where fork is unavailable) batches are made in-process; the batches
    are identical either way.
    """

    def __init__(self, sampler, batch, seed, first_step, workers=1, ahead=3):
        self.sampler, self.batch, self.seed = sampler, int(batch), int(seed)
        self.next = int(first_step)
        self.pool = None
        self.queue = []
        if workers > 0 and "fork" in mp.get_all_start_methods():
            global _PREFETCH_SAMPLER
            _PREFETCH_SAMPLER = sampler          # inherited by the forked worker
            self.pool = mp.get_context("fork").Pool(1)
            for _ in range(ahead):
                self._submit()

    def _submit(self):
        self.queue.append((self.next, self.pool.apply_async(_prefetch_batch, (self.next, self.batch, self.seed))))
        self.next += 1

    def get(self, step):
        if self.pool is None:
            return self.sampler.batch_for_step(step, self.batch, self.seed)
        s, res = self.queue.pop(0)
        if s != step:
            raise RuntimeError(f"prefetcher asked for step {step}, has {s}")
        self._submit()
        return res.get()

    def close(self):
        if self.pool is not None:
            self.pool.terminate()
            self.pool.join()
            self.pool = None


_PREFETCH_SAMPLER = None


def _prefetch_batch(step, batch, seed):
    return _PREFETCH_SAMPLER.batch_for_step(step, batch, seed)


def fixed_batches(clips, n_windows, batch, window=40, kind="manikin", devices=features.INPUT_DEVICES,
                  seed=12345, body=True):
    """A deterministic list of un-augmented batches (validation)."""
    s = WindowSampler(clips, window=window, kind=kind, devices=devices, augment=Augment.off(), seed=seed,
                      body=body)
    out, left = [], int(n_windows)
    while left > 0:
        b = min(batch, left)
        out.append(s.sample(b))
        left -= b
    return out


# --------------------------------------------------------------------------
# synthetic motion (tests, benchmarks, development without BVH data)
@dataclass
class SyntheticMotion:
    """Stand-in for ``core.joint_maps.MotionClip`` (same fields)."""
    fps: float
    positions: np.ndarray
    end_rot: dict
    body: Body
    take_id: str
    name: str = ""


def synthetic_motion(rng, T=120, stature=1.75, fps=MODEL_FPS, take_id="synthetic"):
    """Smooth random motion posed by FK: sums of sinusoids per joint (elbows and
    knees bend as hinges within limits), the pelvis drifting over the floor and
    lowered so the lowest foot joint touches z = 0."""
    body = make_body(float(stature))
    t = np.arange(T) / fps
    freq = rng.uniform(0.2, 1.5, (3, NUM_JOINTS, 3))
    amp = rng.uniform(0.0, 0.35, (3, NUM_JOINTS, 3)) / 3
    phase = rng.uniform(0, 2 * np.pi, (3, NUM_JOINTS, 3))
    aa = (amp[None] * np.sin(2 * np.pi * freq[None] * t[:, None, None, None] + phase[None])).sum(1)
    aa[:, 0] += np.array([0, 0, 1.0]) * rng.uniform(-np.pi, np.pi)            # heading
    local = rot.axis_angle_to_matrix(aa)
    for li, (_, b, m, e) in enumerate(LIMBS):
        flex = 0.6 + 0.5 * np.sin(2 * np.pi * rng.uniform(0.2, 1.0) * t + rng.uniform(0, 6))
        local[:, m] = rot.axis_angle_rotation(np.broadcast_to(ls.H0[li], (T, 3)), flex)
    root = np.zeros((T, 3))
    root[:, :2] = rng.normal(size=2) + np.cumsum(rng.normal(size=(T, 2)) * 0.01, 0)
    P, R = forward_kinematics(local, root, body)
    lowest = P[:, [J["left_ankle"], J["right_ankle"], J["left_foot"], J["right_foot"]], 2].min(1)
    P[..., 2] -= lowest[:, None]
    return SyntheticMotion(fps=float(fps), positions=P, end_rot={j: R[:, j] for j in _END_JOINTS},
                           body=body, take_id=str(take_id), name=str(take_id))
