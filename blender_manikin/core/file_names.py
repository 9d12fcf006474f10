"""File names made from names users give (take, armature, recording names), safe on every
system the outputs travel to.  No bpy.

Windows and macOS compare file names ignoring case (``Take.fbx`` is ``take.fbx``) and, on
macOS, Unicode normalisation (``Übung`` composed, U+00DC, is ``Übung`` decomposed, U+0055
U+0308): two outputs whose names differ only so are one file there, the second over the first,
even when they are two files on Linux.  :func:`fold` is the name as those systems compare it;
:func:`unique_stems` keeps outputs apart by it.
"""
from __future__ import annotations

import unicodedata


#: the longest output stem in UTF-8 bytes: a name (255 bytes on ext4, APFS, NTFS: 255 UTF-16
#: units) must also hold a hash suffix, the extension and a temporary ``.part<pid>`` / ``.tmp``
MAX_STEM_BYTES = 200


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
    same name typed elsewhere give one stem, cut to :data:`MAX_STEM_BYTES`; ``fallback``
    when nothing is left."""
    s = "".join(c if c.isalnum() else "_" for c in unicodedata.normalize("NFC", str(name)))
    return fit_bytes(s) if s.strip("_") else fallback


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
