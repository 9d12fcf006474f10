"""Outputs never replace a file the user made or changed.  Never imports bpy.

The command line (``solve``, ``convert``) writes ``DIR/<take>.<ext>``.  A file already there is
replaced only when it is an output of an earlier run, unchanged since: each folder keeps a record
of the outputs written into it (:data:`RECORD`: name → size and modification time), so a rerun
into the same folder replaces its own results, while a ``take.blend`` an animator opened, worked
in and saved, or a file of the user's own that happens to share the name, stops that input with
an error naming it (``--overwrite`` replaces them anyway).  Outputs are claimed in the record
before they are written (:func:`claim`: the name, no size yet) and recorded when complete
(:func:`record`), so what a killed run left under a claimed name is replaced by the rerun.
"""
from __future__ import annotations

import json
import os

from .file_names import written_whole

#: the record of outputs written into a folder, in that folder
RECORD = ".blender_manikin_outputs"      # JSON; no .json: not taken for an output
#: a record entry of an output claimed and not yet recorded complete
PENDING = "being written"


class OutputInTheWay(ValueError):
    """An output would replace a file that is not an unchanged output of an earlier run."""


def _stat(path):
    st = os.stat(path)
    return {"size": int(st.st_size), "mtime_ns": int(st.st_mtime_ns)}


def _read_record(folder) -> dict:
    try:
        with open(os.path.join(folder, RECORD), encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def in_the_way(paths) -> list:
    """The ``paths`` that exist and are not outputs of an earlier run, unchanged since (their
    size and modification time as the folder's :data:`RECORD` has them)."""
    records, out = {}, []
    for p in paths:
        if not os.path.lexists(p):
            continue
        folder, name = os.path.split(os.path.abspath(p))
        rec = records.setdefault(folder, _read_record(folder))
        try:
            same = os.path.isfile(p) and (rec.get(name) == _stat(p) or rec.get(name) == PENDING)
        except OSError:
            same = False
        if not same:
            out.append(p)
    return out


def check_free(paths, overwrite=False):
    """Raise :class:`OutputInTheWay` naming the ``paths`` that would replace a file the user made or
    changed (:func:`in_the_way`), unless ``overwrite``."""
    if overwrite:
        return
    blocked = in_the_way(paths)
    if blocked:
        names = ", ".join(os.fspath(p) for p in blocked)
        raise OutputInTheWay(f"{names} already exist{'s' if len(blocked) == 1 else ''} and "
                             f"{'is' if len(blocked) == 1 else 'are'} not this tool's unchanged output of an "
                             "earlier run (made or edited since): nothing written; pass --overwrite to replace, "
                             "or choose another --out")


def claim(paths):
    """Note ``paths`` (about to be written; :func:`check_free` passed) in their folders'
    :data:`RECORD` as being written: a run killed before :func:`record` leaves them replaceable."""
    _update(paths, lambda p: PENDING)


def record(paths):
    """Note ``paths`` (just written) in their folders' :data:`RECORD`, as they are now."""
    _update(paths, _stat)


def _update(paths, entry):
    by_folder = {}
    for p in paths:
        folder, name = os.path.split(os.path.abspath(p))
        by_folder.setdefault(folder, []).append((name, p))
    for folder, items in by_folder.items():
        rec = _read_record(folder)
        for name, p in items:
            try:
                rec[name] = entry(p)
            except OSError:
                rec.pop(name, None)
        with written_whole(os.path.join(folder, RECORD)) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as f:
            json.dump(rec, f, indent=0, sort_keys=True)
