"""Outputs never replace a file the user made or changed.  Never imports bpy.

The command line (``solve``, ``convert``) writes ``DIR/<take>.<ext>``.  A file already there is
replaced only when it is an output of an earlier run, unchanged since: each folder keeps a record
of the outputs written into it (:data:`RECORD`: name → size and modification time), so a rerun
into the same folder replaces its own results, while a ``take.blend`` an animator opened, worked
in and saved, or a file of the user's own that happens to share the name, stops that input with
an error naming it (``--overwrite`` replaces them anyway).  Outputs are claimed in the record
before they are written (:func:`claim`: the name, no size yet) and recorded when complete
(:func:`record`), so what a killed run left under a claimed name is replaced by the rerun.

An entry also names the input the output came from (``input``, its absolute path, and
``person``, the label of one person of a keypoint file with several), so a later run names that
input's outputs as before (:func:`recorded_stems`) whatever else shares its batch.  Entries of
older records, without ``input`` (``{"size", "mtime_ns"}`` or the string :data:`PENDING`), still
read: they guard their file as before and name no input.
"""
from __future__ import annotations

import contextlib
import errno
import json
import os

from .file_names import written_whole

#: the record of outputs written into a folder, in that folder
RECORD = ".blender_manikin_outputs"      # JSON; no .json: not taken for an output
#: a record entry of an output claimed and not yet recorded complete (an entry naming its input:
#: ``{"status": PENDING, "input": ...}``)
PENDING = "being written"
#: Windows only: the file locked while a process rewrites the folder's :data:`RECORD` (elsewhere the
#: folder itself is locked, and nothing is added to it)
LOCK = RECORD + ".lock"


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


def _replaceable(entry, path) -> bool:
    """Whether the record ``entry`` of ``path`` says it is this tool's output, unchanged since
    (same size and modification time) or claimed and never recorded complete."""
    if entry == PENDING:
        return True
    if not isinstance(entry, dict):
        return False
    if entry.get("status") == PENDING:
        return True
    st = _stat(path)
    return entry.get("size") == st["size"] and entry.get("mtime_ns") == st["mtime_ns"]


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
            same = os.path.isfile(p) and _replaceable(rec.get(name), p)
        except OSError:
            same = False
        if not same:
            out.append(p)
    return out


def check_free(paths, overwrite=False, remedy="pass --overwrite to replace, or choose another --out"):
    """Raise :class:`OutputInTheWay` naming the ``paths`` that would replace a file the user made or
    changed (:func:`in_the_way`), unless ``overwrite``.  remedy: what the message tells the user
    to do (the command line's options by default; Blender's operators name their own fields)."""
    if overwrite:
        return
    blocked = in_the_way(paths)
    if blocked:
        names = ", ".join(os.fspath(p) for p in blocked)
        raise OutputInTheWay(f"{names} already exist{'s' if len(blocked) == 1 else ''} and "
                             f"{'is' if len(blocked) == 1 else 'are'} not this tool's unchanged output of an "
                             f"earlier run (made or edited since): nothing written; {remedy}")


def _source(source, person) -> dict:
    """The record's fields naming the input ``source`` (made absolute) and ``person`` (a label)."""
    out = {} if source is None else {"input": os.path.abspath(os.fspath(source))}
    if source is not None and person is not None:
        out["person"] = str(person)
    return out


def claim(paths, source=None, person=None, sources=None):
    """Note ``paths`` (about to be written; :func:`check_free` passed) in their folders'
    :data:`RECORD` as being written: a run killed before :func:`record` leaves them replaceable.
    ``source``: the input they are written from (``person``: its person's label), remembered so
    a later run names them alike (:func:`recorded_stems`); ``sources``: ``{path: (input, person)}``
    where the paths come from several inputs (one write of the record for a whole batch)."""
    def entry(p):
        named = _source(*sources[p]) if sources and p in sources else _source(source, person)
        return {"status": PENDING, **named} if named else PENDING
    _update(paths, entry)


def record(paths, source=None, person=None):
    """Note ``paths`` (just written) in their folders' :data:`RECORD`, as they are now, and
    ``source`` / ``person`` as :func:`claim` does."""
    named = _source(source, person)
    _update(paths, lambda p: {**_stat(p), **named})


def input_key(source, person=None):
    """How :func:`recorded_stems` names an input: ``(its absolute path, as the system compares
    paths, person label or None)``."""
    return (os.path.normcase(os.path.abspath(os.fspath(source))), None if person is None else str(person))


def recorded_stems(folder, extensions) -> list:
    """``[(input key, stem), ...]`` of the outputs ``folder``'s :data:`RECORD` says were written
    from a named input (:func:`input_key`; entries of older records name none and are left out),
    oldest first (outputs being written last): ``DIR/take.json`` from ``/in/take.csv`` gives
    ``(("/in/take.csv", None), "take")``.  ``extensions``: the outputs' extensions (``.json``,
    ``.tar.gz``...), the longest that ends a name is taken off it; names ending in none are left
    out, and so are names with a folder in them (``../take.json``, a record edited by hand).
    An absent or unreadable record gives ``[]``."""
    exts = sorted(extensions, key=len, reverse=True)
    found = []
    for name, entry in _read_record(folder).items():
        if not (isinstance(entry, dict) and isinstance(entry.get("input"), str)):
            continue
        if "/" in name or "\\" in name:       # a hand-edited name with a folder: never written outside
            continue
        ext = next((e for e in exts if name.endswith(e) and len(name) > len(e)), None)
        if ext is None:
            continue
        order = float("inf") if entry.get("status") == PENDING else entry.get("mtime_ns", 0)
        person = entry.get("person")
        found.append((order if isinstance(order, (int, float)) else 0,
                      input_key(entry["input"], None if person is None else str(person)), name[:-len(ext)]))
    found.sort(key=lambda t: t[0])
    return [(key, stem) for _, key, stem in found]


@contextlib.contextmanager
def _locked(folder):
    """Hold ``folder``'s :data:`RECORD` for one process at a time while it is read, changed and
    written again: two runs writing into one folder at once (two ``solve``, or ``solve`` beside
    ``convert``) otherwise lose each other's entries (their outputs then read as the user's) or
    fail on the record's temporary file.  The folder is locked (``flock``; Windows: the file
    :data:`LOCK` in it); where the file system cannot lock, the record is written unlocked, as
    before."""
    if os.name == "nt":
        import msvcrt
        try:
            fd = os.open(os.path.join(folder, LOCK), os.O_RDWR | os.O_CREAT)
        except OSError:
            yield
            return
        try:
            locked = True
            while True:
                try:
                    msvcrt.locking(fd, msvcrt.LK_LOCK, 1)      # retries for 10 s, then raises
                    break
                except OSError as exc:
                    if exc.errno != errno.EDEADLOCK:           # not another run's lock: unlocked
                        locked = False
                        break
            try:
                yield
            finally:
                if locked:
                    os.lseek(fd, 0, os.SEEK_SET)
                    msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)
        finally:
            os.close(fd)
        return
    import fcntl
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
        except OSError:                       # a file system without locks
            pass
        yield                                 # closing the folder lets the lock go
    finally:
        os.close(fd)


def _update(paths, entry):
    by_folder = {}
    for p in paths:
        folder, name = os.path.split(os.path.abspath(p))
        by_folder.setdefault(folder, []).append((name, p))
    for folder, items in by_folder.items():
        with _locked(folder):
            rec = _read_record(folder)
            for name, p in items:
                try:
                    rec[name] = entry(p)
                except OSError:
                    rec.pop(name, None)
            with written_whole(os.path.join(folder, RECORD)) as tmp, \
                    open(tmp, "w", encoding="utf-8", newline="\n") as f:
                json.dump(rec, f, indent=0, sort_keys=True)
