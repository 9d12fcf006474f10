"""A Vicon subject's measurements (``.mp`` / ``.vsk``) for Plug-in Gait markers.  No bpy.

Vicon Nexus keeps each subject's measurements, in millimetres, in two files beside the trials:

* ``<Subject>.mp``: text, one ``$Name = Value`` a line (spaces optional), e.g.
  ``$LeftKneeWidth = 104.5``, ``$MarkerDiameter = 14``, ``$Height = 1750``; blank lines and
  comments (a line starting with ``{*``, ``#``, ``//`` or ``;``; a trailing ``{* ... *}``) are
  skipped;
* ``<Subject>.vsk``: XML, ``<StaticParameter NAME="LeftKneeWidth" VALUE="104.5" .../>`` (as Nexus
  writes the subject's measurements; pyCGM2 reads them so) or ``<Parameter NAME=... VALUE=...>``
  (a name may carry a ``Subject:`` or ``Subject_`` prefix); an element without ``VALUE`` (Nexus
  leaves it out of a measurement not taken) is not measured, as 0.  In a file that has
  ``<StaticParameter>`` elements the ``<Parameter>`` ones are the labelling skeleton's fitted
  values (marker offsets, segment lengths; a *FullBody Ai* skeleton's ``WristWidth`` of 32 mm is
  not the subject's wrist), read into :attr:`SubjectParams.raw` but not used as measurements.

Names match case-insensitively.  Read as measurements (:data:`WIDTHS`): ``{Left,Right}{Knee,Ankle,
Elbow,Wrist}Width`` (an unsided ``KneeWidth`` ... applies to both sides, a sided one wins),
``MarkerDiameter`` (default :data:`MARKER_DIAMETER_MM` when a width is given without it) and
``Height`` (the subject's stature).  The knee, ankle and elbow widths place lateral-only joint
centres (:func:`.marker_sets.joint_centres`); the wrist's is read and said in
:meth:`SubjectParams.summary` but not used (Plug-in Gait's wrist is the midpoint of its two wrist
markers).  A value of 0 is "not measured" (Nexus writes 0 for the
measurements left empty); a negative width or height, a value that is not a number, or a line
with no ``=`` is refused with the file and line.  Other parameters (``Bodymass``,
``InterAsisDistance``, ``LeftLegLength``, ``LeftAsisTrocDistance`` ...) are read into
:attr:`SubjectParams.raw` and not used (see docs/FORMATS.md).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

from .marker_sets import marker_subject
from .plain import shown
from .recording import RecordingError, read_text

#: the joints whose ``<Side><Joint>Width`` is read (``LeftKneeWidth``); the wrist's is not used
WIDTHS = ("knee", "ankle", "elbow", "wrist")
#: Plug-in Gait's default marker diameter, millimetres (used when a file gives widths without one)
MARKER_DIAMETER_MM = 14.0
#: the file extensions read
EXTENSIONS = (".mp", ".vsk")


@dataclass
class SubjectParams:
    """A subject's measurements, metres.

    widths: ``{(side, joint): metres}`` (side ``"left"`` / ``"right"``, joint one of
    :data:`WIDTHS`), only those measured (non-zero); marker_diameter: metres (the file's, else
    :data:`MARKER_DIAMETER_MM`); marker_diameter_given: whether the file gave it; height: the
    stature, metres, or None; raw: every parameter read, ``{lower-case name: value in the
    file's unit (mm)}`` (a ``.vsk``'s labelling-skeleton ``<Parameter>`` of a used name under
    ``"parameter:<name>"``, its text); path: the file."""
    path: str
    widths: dict = field(default_factory=dict)
    marker_diameter: float = MARKER_DIAMETER_MM / 1000.0
    marker_diameter_given: bool = False
    height: float | None = None
    raw: dict = field(default_factory=dict)

    def offset(self, side, joint):
        """Metres from the lateral marker's centre to the joint centre, ``width / 2 + marker
        radius`` (Plug-in Gait's), or None where the width was not measured."""
        w = self.widths.get((side, joint))
        return None if w is None else 0.5 * w + 0.5 * self.marker_diameter

    def summary(self) -> str:
        """One line for the read's report: the file and the widths (mm) used, e.g.
        ``"subject Bob.mp: knee 104/106 mm, ankle 70/70 mm (L/R), marker 14 mm, height 1.75 m"``."""
        parts = []
        for j in WIDTHS:
            lw, rw = self.widths.get(("left", j)), self.widths.get(("right", j))
            if lw is None and rw is None:
                continue
            parts.append(f"{j} {_mm(lw)}/{_mm(rw)} mm")
        text = ", ".join(parts) + " (L/R)" if parts else "no joint widths"
        if parts:
            text += f", marker {_mm(self.marker_diameter)} mm" + ("" if self.marker_diameter_given else " (default)")
        if self.height:
            text += f", height {self.height:.3f} m"
        return f"subject {os.path.basename(self.path)}: {text}"


def _mm(metres):
    return "-" if metres is None else f"{metres * 1000.0:g}"


_COMMENT_STARTS = ("{*", "#", "//", ";")


def _parse_mp(text, path):
    """``[(name, value text, line)]`` of an ``.mp`` file's ``$Name = Value`` lines."""
    out = []
    for i, line in enumerate(text.splitlines(), start=1):
        s = re.sub(r"\{\*.*?\*\}", "", line).strip()
        if not s or line.strip().startswith(_COMMENT_STARTS):
            continue
        if "=" not in s:
            raise RecordingError(f"{shown(s)} is not a '$Name = Value' line", path=path, line=i)
        name, value = (p.strip() for p in s.split("=", 1))
        name = name.lstrip("$").strip()
        if not name:
            raise RecordingError(f"{shown(s)} has no name before '='", path=path, line=i)
        out.append((name, value, i))
    return out


def _parse_vsk(text, path):
    """``[(name, value text, line, used)]`` of a ``.vsk`` file's ``<StaticParameter NAME= VALUE=>``
    and ``<Parameter NAME= VALUE=>`` elements (the line is the element's, where the parser tells
    it); one without ``VALUE`` is left out (not measured).  ``used``: whether it may be a
    measurement: every element where the file has no ``<StaticParameter>``, else only those."""
    import xml.etree.ElementTree as ET
    try:
        parser = ET.XMLPullParser(events=("start",))
        parser.feed(text)
        parser.close()
        events = list(parser.read_events())
    except ET.ParseError as exc:
        raise RecordingError(f"not valid XML ({exc})", path=path, line=exc.position[0]) from None
    # ElementTree keeps no line numbers: find each parameter's line by its NAME in the text
    lines = text.splitlines()
    has_static = any(el.tag.rsplit("}", 1)[-1].lower() == "staticparameter" for _, el in events)
    out = []
    for _, el in events:
        tag = el.tag.rsplit("}", 1)[-1].lower()
        if tag not in ("parameter", "staticparameter"):
            continue
        attrs = {k.lower(): v for k, v in el.attrib.items()}
        name = attrs.get("name", "")
        line = next((i for i, t in enumerate(lines, start=1) if f'"{name}"' in t or f"'{name}'" in t), None)
        if not name:
            raise RecordingError("a <Parameter> has no NAME", path=path, line=line)
        if "value" not in attrs:
            continue                    # not measured (Nexus writes no VALUE for it)
        name = name.rsplit(":", 1)[-1]
        out.append((name, attrs["value"].strip(), line, tag == "staticparameter" or not has_static))
    return out


#: the parameter names used: lower case, a Vicon subject prefix dropped
_USED = {f"{s}{j}width" for s in ("", "left", "right") for j in WIDTHS} | {"markerdiameter", "height"}


def _key(name):
    """A parameter's name in lower case with a ``Subject_`` prefix dropped when what follows is a
    name used (``"Bob_LeftKneeWidth"`` → ``"leftkneewidth"``)."""
    k = name.strip().lower()
    if k not in _USED and "_" in k and k.split("_", 1)[1] in _USED:
        k = k.split("_", 1)[1]
    return k


def read_subject_params(path) -> SubjectParams:
    """The measurements of a Vicon ``.mp`` or ``.vsk`` file (see the module doc), metres.
    Raises :class:`.recording.RecordingError` naming the file, the line and the problem."""
    p = os.fspath(path)
    ext = os.path.splitext(p)[1].lower()
    if ext not in EXTENSIONS:
        raise RecordingError(f"not a subject parameter file: expected .mp or .vsk, got {shown(ext or '(none)')}",
                             path=p)
    text = read_text(p)
    if ext == ".mp":
        entries = [(name, value, line, True) for name, value, line in _parse_mp(text, p)]
    else:
        entries = _parse_vsk(text, p)
    raw, lines = {}, {}
    for name, value, line, used in entries:
        k = _key(name)
        if k in _USED and not used:         # a labelling skeleton's <Parameter>: kept, not used
            raw[f"parameter:{k}"] = value
        elif k in _USED:
            try:
                v = float(value)
            except ValueError:
                raise RecordingError(f"{name} = {shown(value)} is not a number", path=p, line=line) from None
            if not v >= 0.0 or v == float("inf"):
                raise RecordingError(f"{name} = {shown(value)}: expected a positive number of millimetres "
                                     "(0: not measured)", path=p, line=line)
            raw[k], lines[k] = v, line
        else:
            raw[k] = value
    out = SubjectParams(path=p, raw=raw)
    for side in ("left", "right"):
        for j in WIDTHS:
            v = raw.get(f"{side}{j}width") or raw.get(f"{j}width")
            if v:
                out.widths[(side, j)] = v / 1000.0
    if raw.get("markerdiameter"):
        out.marker_diameter, out.marker_diameter_given = raw["markerdiameter"] / 1000.0, True
    if raw.get("height"):
        out.height = raw["height"] / 1000.0
        if not 0.5 <= out.height <= 2.8:
            raise RecordingError(f"Height = {shown(raw['height'])} mm: expected a stature in millimetres "
                                 "(500 to 2800)", path=p, line=lines["height"])
    return out


def find_subject_params(trc_path, marker_names):
    """The subject parameter file for a marker file (TRC, C3D), or None: ``<Subject>.mp`` (else ``.vsk``) beside it
    when its marker names carry a ``Subject:`` prefix, else the folder's only ``.mp`` (else its
    only ``.vsk``).  File names match case-insensitively."""
    folder = os.path.dirname(os.path.abspath(os.fspath(trc_path)))
    try:
        files = sorted(f for f in os.listdir(folder) if os.path.isfile(os.path.join(folder, f)))
    except OSError:
        return None
    subjects = {marker_subject(n).lower() for n in marker_names} - {""}
    for ext in EXTENSIONS:
        for f in files:
            stem, e = os.path.splitext(f)
            if e.lower() == ext and stem.lower() in subjects:
                return os.path.join(folder, f)
    if not subjects:
        for ext in EXTENSIONS:
            hits = [f for f in files if os.path.splitext(f)[1].lower() == ext]
            if len(hits) == 1:
                return os.path.join(folder, hits[0])
            if hits:
                return None                 # several: which subject is not told
    return None
