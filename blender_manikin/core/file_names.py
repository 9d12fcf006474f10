"""File names made from names users give (take, armature, recording names), safe on every
system the outputs travel to.  No bpy.

Windows and macOS compare file names ignoring case (``Take.fbx`` is ``take.fbx``) and, on
macOS, Unicode normalisation (``Übung`` composed, U+00DC, is ``Übung`` decomposed, U+0055
U+0308): two outputs whose names differ only so are one file there, the second over the first,
even when they are two files on Linux.  :func:`fold` is the name as those systems compare it;
:func:`unique_stems` keeps outputs apart by it.

Windows also refuses some names outright, whatever system the file is made on (a name made on
Linux must still copy there): :func:`windows_safe` is the one rule for them (device names such
as ``CON`` or ``COM1``, the characters ``<>:"/\\|?*`` and control characters, trailing dots and
spaces), and :func:`fit_stem` keeps a whole path under Windows' classic 260-character limit.
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import re
import unicodedata


#: the longest output stem in UTF-8 bytes: a name (255 bytes on ext4, APFS, NTFS: 255 UTF-16
#: units) must also hold a hash suffix, the extension and a temporary ``.part<pid>`` / ``.tmp``
MAX_STEM_BYTES = 200


#: names Windows keeps for devices: no file may be called so, with any extension (``con.json``,
#: ``Aux.tar.gz``), in any case; ``¹²³`` are the superscript digits Windows also takes as ``1 2 3``
RESERVED = frozenset(["CON", "PRN", "AUX", "NUL"] + [f"{d}{n}" for d in ("COM", "LPT") for n in "0123456789¹²³"])

#: the characters no Windows file name may hold: ``<>:"/\\|?*`` and the control characters
_FORBIDDEN = re.compile(r'[<>:"/\\|?*\x00-\x1f\x7f]')

#: the classic Windows limit of a whole path (``MAX_PATH``), in UTF-16 units, its ending NUL
#: included: a path may hold 259 characters where long paths are not enabled
MAX_PATH = 260

#: whether the limits of Windows apply here (the ``windows`` argument's default)
ON_WINDOWS = os.name == "nt"

#: the shortest stem :func:`fit_stem` cuts to: a few characters of the name, ``-`` and 8 hex digits
MIN_STEM = 12


def windows_safe(stem: str, fallback: str = "take") -> str:
    """``stem`` (a file name without its extension, in any script) made a name Windows accepts,
    on every system so the file can move there: each of ``<>:"/\\|?*`` and each control
    character ``_``; trailing dots and spaces removed (Windows drops them, so ``take.`` and
    ``take`` would be one file); a reserved device name (:data:`RESERVED`: ``CON``, ``nul``,
    ``COM1``, ``LPT¹``..., before the first dot, as Windows reads it) given a ``_`` after it:
    ``con`` -> ``con_``, ``aux.take`` -> ``aux_.take``; ``LPT9-take`` is no device and kept.
    ``fallback`` when nothing is left.  Other names are returned unchanged."""
    s = _FORBIDDEN.sub("_", str(stem)).rstrip(" .")
    if not s:
        return fallback
    head, dot, rest = s.partition(".")
    if head.rstrip(" ").upper() in RESERVED:
        s = head + "_" + dot + rest
    return s


def _units(text: str) -> int:
    """``text``'s length in UTF-16 units, as Windows counts a path (``𝄞``: 2)."""
    return len(str(text).encode("utf-16-le", "surrogatepass")) // 2


def short_hash(key: str) -> str:
    """8 hex digits of the SHA-1 of ``key`` (an input's absolute path): the suffix that keeps
    a shortened or clashing output name apart from others."""
    return hashlib.sha1(str(key).encode("utf-8", "surrogateescape")).hexdigest()[:8]


def stem_room(folder: str, tail: int, windows: bool | None = None):
    """How many UTF-16 units a stem may have so that ``folder``/``stem`` plus ``tail`` more
    units (the extension, a temporary suffix) stays under :data:`MAX_PATH`; ``None`` where the
    limit does not apply (``windows``: default, whether this is Windows).  ``folder`` is made
    absolute first, as Windows counts it."""
    if not (ON_WINDOWS if windows is None else windows):
        return None
    folder = os.path.abspath(folder)
    sep = 0 if folder.endswith(("/", "\\")) else 1
    return MAX_PATH - 1 - _units(folder) - sep - int(tail)


def check_folder(folder: str, tail: int, windows: bool | None = None):
    """:func:`stem_room` of ``folder``; ``ValueError`` naming ``folder`` when it leaves no room
    for a :data:`MIN_STEM`-unit name (call it before making the folder: Windows cannot make it)."""
    room = stem_room(folder, tail, windows)
    if room is not None and room < MIN_STEM:
        raise ValueError(f"output folder {os.path.abspath(folder)}: its path is too long for Windows "
                         f"({_units(os.path.abspath(folder))} characters; a file in it may have at most "
                         f"{MAX_PATH - 1} in all): choose a folder with a shorter path")
    return room


def check_path(path: str, tail: int = 0, windows: bool | None = None) -> str:
    """``path`` (a file the user chose to write: Export FBX's, Save Map's) made absolute, as
    Windows counts it; ``ValueError`` naming it when, with ``tail`` more characters (a temporary
    suffix), it is longer than Windows' :data:`MAX_PATH` allows (259 characters; ``windows``:
    default, whether this is Windows; elsewhere any length passes), said before anything is
    written instead of the exporter's or the system's own failure."""
    full = os.path.abspath(os.fspath(path))
    if (ON_WINDOWS if windows is None else windows) and _units(full) + int(tail) > MAX_PATH - 1:
        raise ValueError(f"{full}: the path is too long for Windows ({_units(full)} characters; a file may have "
                         f"at most {MAX_PATH - 1 - int(tail)} here): choose a shorter name or a folder "
                         "nearer the drive's top")
    return full


def fit_stem(stem: str, key: str, folder: str, tail: int, windows: bool | None = None) -> str:
    """``stem`` as it fits ``folder`` under :data:`MAX_PATH` (:func:`stem_room`): unchanged when
    it fits (always, off Windows), else cut and given ``-`` and :func:`short_hash` of ``key``,
    so two long names cut alike stay apart.  ``ValueError`` naming ``folder`` when not even a
    :data:`MIN_STEM`-unit name fits."""
    room = check_folder(folder, tail, windows)
    if room is None or _units(stem) <= room:
        return stem
    keep, n = [], 0
    for c in stem:
        n += _units(c)
        if n > room - 9:
            break
        keep.append(c)
    return windows_safe("".join(keep), "take") + "-" + short_hash(key)


def fit_bytes(name: str, limit: int = MAX_STEM_BYTES) -> str:
    """``name`` cut to at most ``limit`` bytes of UTF-8, at a character boundary."""
    b = str(name).encode("utf-8", "surrogateescape")
    return name if len(b) <= limit else b[:limit].decode("utf-8", "ignore")


def fold(name: str) -> str:
    """``name`` as a case-insensitive file system compares it: NFC, case folded."""
    return unicodedata.normalize("NFC", str(name)).casefold()


def file_stem(name: str, fallback: str = "take") -> str:
    """``name`` as a file name without extension: letters and digits of any script kept
    (``Übung``, ``テイク``, ``café``), every other character ``_`` (spaces, ``.``, ``/``, ``:``,
    ``*``, ``#``, ``%``...: the characters Windows forbids and those URLs and shells treat
    specially); for ASCII names this is ``bpy.path.clean_name``.  NFC, so a macOS name and the
    same name typed elsewhere give one stem, cut to :data:`MAX_STEM_BYTES`; a Windows device
    name given a ``_`` (:func:`windows_safe`: ``CON`` -> ``CON_``); ``fallback`` when nothing
    is left."""
    s = "".join(c if c.isalnum() else "_" for c in unicodedata.normalize("NFC", str(name)))
    return windows_safe(fit_bytes(s), fallback) if s.strip("_") else fallback


def unique_stems(stems) -> list:
    """``stems`` in order, each one that :func:`fold` makes equal to an earlier one given a
    ``_2``, ``_3``... suffix (the first keeps its name), so none is another's file on
    Windows or macOS."""
    seen, out = set(), []
    for s in stems:
        cand, k = s, 1
        while fold(cand) in seen:
            k += 1
            cand = f"{s}_{k}"
        seen.add(fold(cand))
        out.append(cand)
    return out


def person_stems(stem: str, labels, key: str = "", folder: str | None = None, tail: int = 0,
                 windows: bool | None = None) -> list:
    """``<stem>_p<label>`` for each of a keypoint file's people ``labels`` (their outputs,
    side by side): :func:`file_stem` makes a label a file name, :func:`unique_stems` keeps two
    labels that come out alike apart, and with ``folder`` each is :func:`fit_stem` cut to fit it
    under Windows' 260 characters with ``tail`` more (the hash of ``key``, the input's absolute
    path, and the label, so two people cut alike stay apart).  A ``stem`` that
    :func:`windows_safe` gave a ``_`` for a device name (``con`` -> ``con_``) loses it: the
    suffix already makes the name one Windows accepts (``con_p1``, as Blender names the take
    of ``con.csv``'s person 1, not ``con__p1``)."""
    if stem.endswith("_") and windows_safe(stem[:-1]) == stem:
        stem = stem[:-1]
    stems = unique_stems([windows_safe(f"{stem}_p{file_stem(lab, 'x')}") for lab in labels])
    if folder is None:
        return stems
    return [fit_stem(s, f"{key}#person={lab}", folder, tail, windows) for s, lab in zip(stems, labels)]


def keep_people_apart(names: dict, people, taken=(), folder: str | None = None, tail: int = 0,
                      windows: bool | None = None) -> dict:
    """``names`` (``{key: output stem}``, a key an input or ``(input, person label)``) with each
    stem of a key in ``people`` (a person's ``<stem>_p<label>``, :func:`person_stems`) that
    :func:`fold` makes equal to another key's stem, or to one of ``taken`` (other inputs' stems),
    given ``-`` and the :func:`short_hash` of its key (the input's absolute path and the label, so
    ``solve`` and ``convert`` name it alike): ``group.npy``'s person 0 and a file
    ``group_p0.npy`` beside it never write one ``group_p0.json``.  With ``folder``, a stem so
    lengthened is :func:`fit_stem` cut to fit it on Windows."""
    people = set(people)
    count = {}
    for s in list(names.values()) + list(taken):
        count[fold(s)] = count.get(fold(s), 0) + 1
    out = {}
    for k, s in names.items():
        if k in people and count[fold(s)] > 1:
            key = f"{os.path.abspath(k[0])}#person={k[1]}" if isinstance(k, tuple) else os.path.abspath(k)
            s = f"{s}-{short_hash(key)}"
            if folder is not None:
                s = fit_stem(s, key, folder, tail, windows)
        out[k] = s
    return out


@contextlib.contextmanager
def written_whole(path, suffix: str = ".tmp"):
    """Yield the temporary name ``path + suffix`` to write ``path`` under; renamed to ``path``
    when the block ends, removed when it raises (an error, Ctrl-C): an interrupted write leaves
    neither a half-written ``path`` nor its temporary behind."""
    tmp = os.fspath(path) + suffix
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise
