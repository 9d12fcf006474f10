"""Dataset-scale conversion without Blender, on Dask: one task per recording, on a laptop's
``LocalCluster`` or on a cluster (SLURM/PBS through dask-jobqueue, Kubernetes through
dask-kubernetes: any ``distributed`` scheduler address).

    blender-manikin convert INPUTS... --out DIR --format json,npz,bvh [--scheduler local|ADDRESS]
        [--workers N] [solve options: --fps, --height, --offsets, --axes, --units, ...]

* Inputs: files, folders (their recordings, recursively), globs, or manifest files (``.txt`` /
  ``.lst``: one path a line, ``#`` comments, relative paths from the manifest's folder;
  ``.jsonl``: objects with a ``path``).  The output folder is never searched for inputs (it may
  sit inside an input folder).
* Each worker loads the model once; each input is one task that reads one recording, solves it
  (:func:`.solve.solve_recording`) and writes ``DIR/STEM.<ext>`` per format under a temporary
  name, renamed when complete, so memory per worker is bounded by one recording.
* A keypoint file with several people (:func:`.io_keypoints.read_keypoint_people`) and the
  person setting ``all`` (the default) is one task per person, each written to
  ``DIR/STEM_p<label>.<ext>`` as ``solve`` names them (:func:`.file_names.person_stems`); its
  manifest lines carry ``person`` (the label) and ``people`` (all of the file's), and each person
  is done, skipped or redone on its own as an input is.  The file is parsed once to list its
  people, then once per worker that solves any of them: a worker keeps the last group file it
  parsed (one file, :func:`.io_keypoints.reusing_loads`) for its next person of that file, and
  drops it after the file's last person or before another file; every worker drops it when the run ends.
* ``DIR/manifest.jsonl`` gets one line per finished input: status (``ok``/``error``), frames,
  seconds, stature, quality notes, outputs, the error, and the input's size and modification
  time when it was read (``source``).  A rerun skips the inputs already converted (every output
  present, one in each format asked for, the input unchanged since: same size and modification
  time), so a crashed or killed job resumes where it stopped, a rerun with more formats writes
  them, and an input replaced since (same name, new content) is converted again; a line cut off
  by a crash is ignored (and never swallows the next run's first line); a bad
  file never stops the others, and neither does a worker that dies on one (killed for memory:
  that input is an error).  The last line says how many converted, failed and were skipped, and
  where the manifest is.  The exit code is 0 only when every input converted (130 after Ctrl-C;
  2 when the scheduler cannot be reached).

Needs the ``[dask]`` extra (``dask[distributed]``); no bpy.
"""
from __future__ import annotations

import contextlib
import glob
import json
import os
import re
import sys
import threading
import time

from . import formats, output_guard
from .file_names import (check_folder, fit_bytes, fit_stem, fold, keep_people_apart, person_stems, short_hash,
                         windows_safe)
from .solve import SolveSettings, error_message, solve_recording

MANIFEST = "manifest.jsonl"
_MANIFEST_SUFFIXES = (".txt", ".lst", ".jsonl")


# --------------------------------------------------------------------------
# inputs and outputs
def _is_recording(path):
    return formats.is_recording_file(path)


def collect_inputs(items, exclude=()):
    """Absolute paths of the recordings named by ``items`` (files, folders, globs, manifests),
    in order, without duplicates.  Folders searched and globs skip what lies under a folder of
    ``exclude`` (the output folder: its ``.npz`` outputs are not inputs when it sits inside an
    input folder).  Raises ``ValueError`` naming an item that gives nothing."""
    skip = [os.path.realpath(os.path.expanduser(str(e))) for e in exclude]

    def kept(p):
        real = os.path.realpath(p)
        return not any(real == e or real.startswith(e + os.sep) for e in skip)

    out = []
    for item in items:
        item = os.path.expanduser(str(item))
        if os.path.isdir(item):
            found = sorted(_walk_recordings(item, kept))
        elif os.path.isfile(item) and item.lower().endswith(_MANIFEST_SUFFIXES) and not _is_recording(item):
            found = _read_manifest_file(item)
        elif os.path.isfile(item):
            found = [item]
        else:
            found = sorted(glob.glob(item, recursive=True))
            if not found:
                raise ValueError(f"{item}: no such file, folder or matching files")
            found = [p for p in found if kept(p)]
        out.extend(os.path.abspath(p) for p in found)
    return list(dict.fromkeys(out))


def _walk_recordings(folder, kept=lambda p: True):
    """Recordings under ``folder``: files with a reader's extension, and FreeMoCap recording
    folders and folders of per-frame JSON keypoints (one input each; their own files are not
    inputs; an output folder holding a ``keypoints3d`` folder is one, and its other recordings
    and sub-folders are searched as any folder's); folders for which ``kept(path)``
    is false are not searched."""
    from .io_keypoints import freemocap_body_file, json_frames_folder
    for d, dirs, fs in os.walk(folder):
        if not kept(d):
            dirs[:] = []
            continue
        frames = json_frames_folder(d)
        if freemocap_body_file(d) or (frames is not None and os.path.normpath(frames) == os.path.normpath(d)):
            dirs[:] = []
            yield d
            continue
        if frames is not None:        # d holds keypoints3d/: d is that input, not its files
            dirs[:] = [s for s in dirs if s.lower() != os.path.basename(frames).lower()]
            yield d
        dirs.sort()
        yield from (p for p in (os.path.join(d, f) for f in fs) if _is_recording(p))


def _read_manifest_file(path):
    base = os.path.dirname(os.path.abspath(path))
    paths = []
    from .recording import read_text
    for n, line in enumerate(read_text(path).splitlines(), 1):     # a BOM is not part of a path
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if path.lower().endswith(".jsonl"):
            try:
                line = json.loads(line)["path"]
            except (json.JSONDecodeError, KeyError, TypeError):
                raise ValueError(f"{path}, line {n}: expected a JSON object with a 'path'") from None
        p = os.path.expanduser(line)
        paths.append(p if os.path.isabs(p) else os.path.join(base, p))
    return paths


def output_stems(paths, out_dir=None, tail=0, windows=None, taken=()):
    """``{input: output stem}``: the file (or FreeMoCap folder) name without extension, made unique
    with a short hash of the input's absolute path when two inputs share a name (in different
    folders, or side by side with different extensions: ``take.csv`` and ``take.bsor``).  Names
    are compared as Windows and macOS compare file names (:func:`.file_names.fold`: ``Take.csv``
    and ``take.csv``; ``Übung`` composed and decomposed), so an output folder on such a disk (or
    shared with one) never gets one output over another.  Every name is one Windows accepts, on
    every system (:func:`.file_names.windows_safe`: ``con.bsor`` -> ``con_``, ``a:b.csv`` ->
    ``a_b``).  A name longer than :data:`.file_names.MAX_STEM_BYTES` (UTF-8) is cut there and
    given the hash too: a file system's 255-byte names must hold the stem, the extension and the
    temporary ``.part`` suffix the output is written under first.  With ``out_dir``, on Windows
    (``windows``: default, whether this is Windows) a name is also cut, with the hash, so the
    whole path with ``tail`` more characters (extension, temporary suffix) stays under 260
    (:func:`.file_names.fit_stem`); ``ValueError`` naming ``out_dir`` when even a short name
    cannot.  ``taken``: stems already used in ``out_dir`` (other inputs' outputs of earlier runs):
    a name one of them takes is given the hash too."""
    stems = {p: windows_safe(os.path.splitext(os.path.basename(os.path.abspath(p)))[0]) for p in paths}
    counts = {}
    for s in list(stems.values()) + list(taken):
        counts[fold(s)] = counts.get(fold(s), 0) + 1

    def stem(p, s):
        short = fit_bytes(s)
        if counts[fold(s)] > 1 or short != s:
            s = f"{short}-{short_hash(os.path.abspath(p))}"
        return s if out_dir is None else fit_stem(s, os.path.abspath(p), out_dir, tail, windows)
    return {p: stem(p, s) for p, s in stems.items()}


def folder_stems(inputs, people, out_dir, tail=0, windows=None) -> dict:
    """``{(input, person label or None): output stem}`` for ``inputs`` (paths) and ``people``
    (``{input: [labels]}`` of the keypoint files with several people; the others are one key
    each, ``(input, None)``), named so that they do not depend on which other inputs share the
    batch: an input (a person) an earlier run wrote into ``out_dir`` keeps the stem its
    outputs have there (:func:`.output_guard.recorded_stems`: the folder's record names the
    input of each output), and a new one gets :func:`output_stems`' name, with the hash where it
    is another input's of this batch or one the record holds for any input (people:
    :func:`.file_names.person_stems` of the file's stem, :func:`.file_names.keep_people_apart`
    so).  ``solve``'s names; ``tail`` and ``windows`` as :func:`output_stems`."""
    exts = {w.extension for w in formats.WRITERS.values()}
    recorded = output_guard.recorded_stems(out_dir, exts)
    own = dict(recorded)                       # the latest stem of each recorded input (person)
    taken = [s for _, s in recorded]

    def kept(p, lab):
        return own.get(output_guard.input_key(p, lab))
    keys = [(p, None) if not people.get(p) else (p, str(lab)) for p in inputs for lab in (people.get(p) or [None])]
    names, used = {}, set()
    for k in keys:
        s = kept(*k)
        if s and fold(s) not in used:          # (two inputs recorded under one name: the first keeps it)
            names[k] = s
            used.add(fold(s))
    bases = {p: kept(p, None) for p in inputs if kept(p, None) and fold(kept(p, None)) not in
             {fold(s) for k, s in names.items() if k[0] != p}}
    # a new name only for an input with a key (itself, a person) not kept: a file whose people all
    # keep theirs is no other's namesake in this batch
    new = [p for p in inputs if p not in bases and any(k not in names for k in keys if k[0] == p)]
    bases.update(output_stems(new, out_dir, tail, windows, taken=taken + list(names.values())))
    for p in inputs:
        labels = [str(lab) for lab in (people.get(p) or [])]
        if not labels:
            names.setdefault((p, None), bases.get(p))
            continue
        if all((p, lab) in names for lab in labels):
            continue
        for lab, s in zip(labels, person_stems(bases[p], labels, os.path.abspath(p), out_dir, tail, windows)):
            names.setdefault((p, lab), s)
    fresh = [k for k in keys if k[1] is not None and kept(*k) != names[k]]
    return keep_people_apart(names, fresh, [s for s in taken if fold(s) not in used], out_dir, tail, windows)


def temp_tail(fmts) -> int:
    """The most characters :func:`convert_task` writes after a stem, around it, in ``DIR``: the
    leading ``.``, ``.part<pid>`` (10 digits at most), the longest extension of ``fmts`` and a
    writer's own ``.tmp.npz``.  :func:`output_stems`' ``tail``."""
    ext = max((len(formats.WRITERS[f].extension) for f in fmts if f in formats.WRITERS), default=0)
    return len(".") + len(".part") + 10 + ext + len(".tmp.npz")


def recorded_stem(record, out_dir):
    """The stem of the outputs ``record`` (a manifest record) says were written in ``out_dir``
    (``DIR/con__p1.bvh`` -> ``con__p1``); None without one there."""
    exts = sorted({w.extension for w in formats.WRITERS.values()}, key=len, reverse=True)
    for p in (record or {}).get("outputs", []):
        if os.path.dirname(os.path.abspath(p)) == os.path.abspath(out_dir):
            name = os.path.basename(p)
            ext = next((e for e in exts if name.endswith(e)), None)
            if ext and len(name) > len(ext):
                return name[:-len(ext)]
    return None


def task_key(path, person=None):
    """The manifest's key of a task: the input ``path``, or ``(path, label)`` for one person of a
    keypoint file with several."""
    return path if person is None else (path, str(person))


def read_manifest(out_dir):
    """The records of ``DIR/manifest.jsonl`` by :func:`task_key` (the input's path; ``(path,
    label)`` for a person of a file with several), the last record per key winning; ``{}`` when
    absent.  A line cut off by a crash is ignored."""
    path = os.path.join(out_dir, MANIFEST)
    records = {}
    if os.path.isfile(path):
        with open(path, encoding="utf-8") as f:
            for line in f:
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:
                    continue
                if isinstance(rec, dict) and "input" in rec:
                    records[task_key(rec["input"], rec.get("person"))] = rec
    return records


def input_signature(path):
    """``{"size": bytes, "mtime_ns": ns}`` of the input ``path`` as it is now (a FreeMoCap folder:
    its files' total size and latest modification time); ``None`` when it cannot be read.
    A rerun compares it with the manifest's ``source`` to find inputs replaced since."""
    try:
        if os.path.isdir(path):
            size = mtime = 0
            for d, _, fs in os.walk(path):
                for f in fs:
                    st = os.stat(os.path.join(d, f))
                    size, mtime = size + st.st_size, max(mtime, st.st_mtime_ns)
            return {"size": int(size), "mtime_ns": int(mtime)}
        st = os.stat(path)
        return {"size": int(st.st_size), "mtime_ns": int(st.st_mtime_ns)}
    except OSError:
        return None


def is_done(record, fmts=()):
    """Whether ``record`` converted its input, every output is present, one is in each of ``fmts``,
    and the input is the one converted (its size and modification time as recorded in ``source``;
    a record without ``source``, from an older manifest, is taken as it is)."""
    outputs = record.get("outputs", []) if record else []
    return (bool(record) and record.get("status") == "ok" and all(os.path.isfile(p) for p in outputs)
            and all(any(p.endswith(formats.WRITERS[f].extension) for p in outputs) for f in fmts)
            and ("source" not in record or record["source"] == input_signature(record["input"])))


def _open_manifest(out_dir):
    """``DIR/manifest.jsonl`` opened to append; a last line a crash cut off (no newline) is ended
    first, so the next record starts a line of its own instead of being lost with it."""
    path = os.path.join(out_dir, MANIFEST)
    man = open(path, "a+b")
    if man.tell():
        man.seek(-1, os.SEEK_END)
        if man.read(1) != b"\n":
            man.write(b"\n")
    man.close()
    return open(path, "a", encoding="utf-8", newline="\n")   # one byte a line break, on Windows too


# --------------------------------------------------------------------------
# one task (runs on a worker)
def convert_task(path, out_dir, stem, fmts, settings, model=None, options=None, person=None, people=None):
    """Convert one recording (with ``person``: that person of a keypoint file with several,
    ``people`` all of its labels); returns its manifest record (never raises for a bad file)."""
    from . import model_choice, pipeline
    from .io_keypoints import forget_loads, reusing_loads
    t0 = time.perf_counter()
    rec = _error_record(path, None, person, people)    # its source before reading: a change after shows
    if person is None:
        forget_loads()                # a group file kept by a person's task before: not needed now
    try:
        st = SolveSettings(**(settings if person is None else dict(settings, person=person)))
        spec = model if model is not None else st.model

        def solver(targets, body, progress=None):
            # one onnxruntime thread per worker; each worker loads a model once (load_model's cache)
            plan = model_choice.plan_models(targets, spec, threads=1)
            return pipeline.solve(targets, body, plan, progress=progress, overlap=st.overlap)

        # a person's task: the group file this worker parsed for another of its people is not
        # parsed again (one file kept per worker: io_keypoints.reusing_loads)
        with reusing_loads() if person is not None else contextlib.nullcontext():
            out = solve_recording(path, st, solver=solver)
        for fmt in fmts:
            writer = formats.WRITERS[fmt]
            dst = os.path.join(out_dir, stem + writer.extension)
            tmp = os.path.join(out_dir, f".{stem}.part{os.getpid()}{writer.extension}")
            writer.write(tmp, out.result, source=os.path.basename(path), options=options)
            os.replace(tmp, dst)
            rec["outputs"].append(dst)
        rec.update(status="ok", frames=int(out.result.num_frames), stature=round(float(out.body.stature), 4),
                   notes=list(out.result.notes) + list(out.result.quality_notes())
                   + [n for n in out.info if not n.startswith("calibrated")])
    except Exception as exc:          # one bad file never stops the others
        rec["error"] = error_message(exc)
    if person is not None and people and str(person) == str(people[-1]):
        forget_loads()                # the file's last person (tasks are queued in order): not kept on
    rec["seconds"] = round(time.perf_counter() - t0, 3)
    return rec


# --------------------------------------------------------------------------
class SchedulerUnreachable(ValueError):
    """The Dask scheduler named by ``--scheduler`` did not answer in time."""


def _client(scheduler, workers, timeout=None):
    """``(Client, LocalCluster or None)``.  A local cluster's workers ignore Ctrl-C (the job
    stops them), get one task at a time each (a worker that dies takes only its own input with
    it) and a task that killed two workers is given up (an error, not four more tries); a
    scheduler ``ADDRESS`` that does not answer within ``timeout`` seconds (default: Dask's
    ``distributed.comm.timeouts.connect``, 30 s) raises :class:`SchedulerUnreachable`."""
    import signal

    import dask
    from distributed import Client, LocalCluster
    if scheduler in (None, "", "local"):
        n = int(workers or os.cpu_count() or 1)
        main = threading.current_thread() is threading.main_thread()   # signal() works there only
        old = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None   # inherited by the workers
        try:
            with dask.config.set({"distributed.scheduler.worker-saturation": 1.0,
                                  "distributed.scheduler.allowed-failures": 1}):
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0")
        finally:
            if main:
                signal.signal(signal.SIGINT, old)
        return Client(cluster), cluster
    if timeout is None:
        timeout = dask.utils.parse_timedelta(dask.config.get("distributed.comm.timeouts.connect"), "s")
    try:
        return Client(scheduler, timeout=timeout), None
    except (OSError, TimeoutError) as exc:
        raise SchedulerUnreachable(f"cannot reach the Dask scheduler at {scheduler} within {timeout:g} s ({exc}); "
                                   "is it running, and is the address right (tcp://HOST:PORT)?") from None


def _forget_on_workers(client):
    """Drop the group file each worker of ``client`` keeps (:func:`.io_keypoints.forget_loads`):
    kept past the run, its arrays would stay in a long-lived worker's memory, and a file rewritten
    with the same size within the disk's time resolution would be solved from the old parse.  A
    worker that does not answer is left as it is."""
    from .io_keypoints import forget_loads
    try:
        client.run(forget_loads, on_error="ignore")
    except Exception:                 # the scheduler gone: its workers with it, nothing kept to drop
        pass


def _error_record(path, message, person=None, people=None):
    rec = {"input": path, "status": "error", "outputs": [], "frames": 0, "seconds": 0.0, "stature": None,
           "notes": [], "error": message, "source": input_signature(path)}
    if person is not None:
        rec.update(person=str(person), people=list(people or ()))
    return rec


def said(rec_or_path, person=None) -> str:
    """How a log line names a task: the input's path, and ``[person LABEL]`` for one person."""
    if isinstance(rec_or_path, dict):
        rec_or_path, person = rec_or_path["input"], rec_or_path.get("person")
    return rec_or_path if person is None else f"{rec_or_path} [person {person}]"


def people_tasks(inputs, settings: SolveSettings, done=None):
    """``[(input, person label or None, all labels or None), ...]``: one task per input, and for a
    keypoint file with several people and ``settings.person`` ``"all"`` one per person
    (:func:`.io_keypoints.keypoint_person_labels`: the file is loaded, no person read; a file
    where only one person is seen long enough gives that one, written under the file's name).  The
    people of an input that ``done`` (:func:`read_manifest`) already holds, unchanged since
    (same ``source``), are taken from it without reading the file (and one converted whole is
    one task, not read either).  A file that cannot be read
    is one task (its error is said by the solve)."""
    from .io_keypoints import is_keypoint_input, keypoint_person_labels
    from .recording import RecordingError
    every = str(settings.person or "all").strip().lower() == "all"
    known = {}
    for rec in (done or {}).values():
        if rec.get("person") is not None and rec.get("people"):
            known.setdefault(rec["input"], []).append(rec)
    tasks = []
    for p in inputs:
        labels = None
        if every:
            sig = input_signature(p)
            seen = [r for r in known.get(p, ()) if r.get("source") == sig]
            whole = (done or {}).get(p)
            if seen and sig is not None:
                labels = list(seen[-1]["people"])
            elif whole and whole.get("status") == "ok" and sig is not None and whole.get("source") == sig:
                labels = None       # converted whole before, unchanged since: one person, not read again
            else:
                try:
                    if is_keypoint_input(p):
                        labels = keypoint_person_labels(p, layout=settings.keypoint_layout, rate=settings.rate,
                                                        mapping=settings.mapping,
                                                        subject_params=settings.subject_params,
                                                        person_axis=settings.person_axis)
                except (RecordingError, OSError, ValueError):
                    labels = None
        if labels:              # one seen of several: solved as that person, under the file's own name
            tasks.extend((p, lab, labels) for lab in labels)
        else:
            tasks.append((p, None, None))
    return tasks


def _lost_task_message(exc):
    """What a task that returned no record (its worker died, it was cancelled) tells the user."""
    from distributed import KilledWorker
    if isinstance(exc, KilledWorker):
        return ("the Dask worker converting it died (killed: out of memory, or a crash in a native library); "
                "the input is not converted (see the worker's log)")
    return f"the Dask task failed: {type(exc).__name__}: {exc}"


def summary(out_dir, ok, errors, skipped, left=0):
    """The last line of a run: how many inputs converted, failed, were skipped (converted before)
    and were left (interrupted), and where the manifest is."""
    text = f"{ok} converted, {errors} error(s), {skipped} skipped (converted before)"
    if left:
        text += f", {left} not converted (interrupted)"
    return text + f"; manifest: {os.path.join(out_dir, MANIFEST)}"


#: the temporary names :func:`convert_task` writes under (then renames): ``.<stem>.part<pid><ext>``,
#: and a writer's own temporary next to it (``...<ext>.tmp``, ``....tmp.npz``)
_PARTIAL = re.compile(r"^\..+\.part\d+\.[A-Za-z0-9]+(\.tmp(\.npz)?)?$")


def remove_partial_outputs(out_dir) -> int:
    """Delete the half-written outputs a killed run left in ``out_dir`` (only this tool's own
    temporary names, :data:`_PARTIAL`); returns how many."""
    n = 0
    for name in os.listdir(out_dir):
        if _PARTIAL.match(name):
            try:
                os.remove(os.path.join(out_dir, name))
                n += 1
            except OSError:
                pass
    return n


def run(inputs, out_dir, fmts, settings: SolveSettings, scheduler=None, workers=None, model=None, options=None,
        progress=True, log=None, connect_timeout=None, report=None, dry_run=False):
    """Convert ``inputs`` (paths) into ``out_dir``; returns ``(exit code, records of this run)``
    and logs :func:`summary` last; ``report(record)``, when given, is called as each input finishes
    (the command line prints its ``OK`` lines so, before the summary).  An input whose worker died
    is an error in the manifest; Ctrl-C logs the summary so far and raises ``KeyboardInterrupt``
    (the manifest holds every input finished).  Raises :class:`SchedulerUnreachable` when
    ``scheduler`` (an address) does not answer within ``connect_timeout`` seconds (default:
    Dask's connect timeout, 30 s).  ``dry_run``: nothing is written (not even ``out_dir``, the
    manifest or a partial output removed) and no Dask started; the records returned are the blocked
    inputs' errors, then ``{"input", "person", "status": "planned" or "skipped", "outputs"}`` for
    each task (the outputs it would write, or a skipped one's), with exit code 1 when any is blocked."""
    import dataclasses
    from distributed import as_completed
    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    bad = [f for f in fmts if f not in formats.WRITERS or formats.WRITERS[f].needs_blender]
    if bad:
        raise ValueError(f"convert writes {', '.join(n for n, w in formats.WRITERS.items() if not w.needs_blender)}"
                         f" (without Blender); not {', '.join(bad)}")
    out_dir = os.path.abspath(out_dir)       # the manifest's outputs hold wherever a rerun starts
    check_folder(out_dir, temp_tail(fmts))   # a folder too deep for Windows' 260 characters: said first
    if not dry_run:
        os.makedirs(out_dir, exist_ok=True)
    removed = 0 if dry_run else remove_partial_outputs(out_dir)
    if removed:
        log(f"removed {removed} partial output(s) a killed run left in {out_dir}")
    done = read_manifest(out_dir)
    # the names of earlier runs' inputs count too: a later take.csv never writes over an earlier one's
    earlier = [r["input"] for r in done.values()]
    stems = output_stems(list(dict.fromkeys(list(inputs) + earlier)), out_dir, temp_tail(fmts))
    # a keypoint file with several people: one task each, <stem>_p<label>, done or redone on its own
    tasks = people_tasks(inputs, settings, done)
    names = {}
    for p, person, people in tasks:
        if person is None or len(people) < 2:
            names[task_key(p, person)] = stems[p]
        elif task_key(p, person) not in names:
            for lab, st in zip(people, person_stems(stems[p], people, os.path.abspath(p), out_dir, temp_tail(fmts))):
                names[task_key(p, lab)] = st
    # a person's <stem>_p<label> never the name of another input's outputs (group_p0.npy beside group.npy)
    split_keys = [task_key(p, person) for p, person, people in tasks if person is not None and len(people) > 1]
    names = keep_people_apart(names, split_keys, [s for p, s in stems.items() if p not in inputs],
                              out_dir, temp_tail(fmts))
    # an input's (a person's) outputs an earlier run wrote keep their name (take.json, though a
    # namesake joined the batch since; con__p1: device-named files' people had a doubled _ before),
    # so a rerun adds a format to them or replaces them, never a second set beside stale ones
    for key in [task_key(*t[:2]) for t in tasks]:
        old = recorded_stem(done.get(key), out_dir)
        if old and old != names[key] and all(fold(old) != fold(s) for k, s in names.items() if k != key):
            names[key] = old
    split = sum(person is not None and len(people) > 1 for _, person, people in tasks)
    if split:
        log(f"{split} people of {len({p for p, person, _ in tasks if person is not None})} keypoint file(s) "
            "with several: converted each on their own")
    todo = [t for t in tasks if not is_done(done.get(task_key(*t[:2])), fmts)]
    skipped = len(tasks) - len(todo)
    if skipped:
        log(f"{skipped} of {len(tasks)} input(s) already converted (manifest): skipped")
    changed = [t for t in todo if task_key(*t[:2]) in done and "source" in done[task_key(*t[:2])]
               and is_done({**done[task_key(*t[:2])], "source": input_signature(t[0])}, fmts)]
    if changed:
        log(f"{len(changed)} input(s) changed since converted (size or modification time): converted again")
    # an output that would replace a file the user made or changed stops its input (output_guard)
    blocked = []
    for p, person, people in todo:
        try:
            output_guard.check_free([os.path.join(out_dir, names[task_key(p, person)] + formats.WRITERS[f].extension)
                                     for f in fmts], bool(getattr(options, "overwrite", False)))
        except output_guard.OutputInTheWay as exc:
            rec = _error_record(p, str(exc), person, people)
            del rec["source"]
            blocked.append(rec)
    gone = {task_key(r["input"], r.get("person")) for r in blocked}
    todo = [t for t in todo if task_key(*t[:2]) not in gone]
    if dry_run:
        plan = []
        for p, person, people in tasks:
            key = task_key(p, person)
            if key in gone:
                continue
            rec = {"input": p, "person": person}
            if any(t[:2] == (p, person) for t in todo):
                rec.update(status="planned",
                           outputs=[os.path.join(out_dir, names[key] + formats.WRITERS[f].extension) for f in fmts])
            else:
                rec.update(status="skipped", outputs=list(done[key].get("outputs", [])))
            plan.append(rec)
        for rec in blocked:
            log(f"ERROR {said(rec)}: {rec['error']}")
        log(f"dry run: {len(todo)} to convert, {skipped} skipped, {len(blocked)} error(s); nothing written")
        return (1 if blocked else 0), blocked + plan
    if blocked:
        with _open_manifest(out_dir) as man:
            for rec in blocked:
                man.write(json.dumps(rec) + "\n")
                log(f"ERROR {said(rec)}: {rec['error']}")
    if not todo:
        log(summary(out_dir, 0, len(blocked), skipped))
        return 0 if all(is_done(done.get(task_key(*t[:2])), fmts) for t in tasks) else 1, blocked
    client, cluster = _client(scheduler, workers, timeout=connect_timeout)
    # claimed before they are written: what a killed run leaves under these names is replaceable
    # the record names each output's input, and its person where the file's people are written apart
    # (one person alone is written under the file's own name, as solve writes it: no person)
    claimed = {os.path.join(out_dir, names[task_key(*t[:2])] + formats.WRITERS[f].extension):
               (t[0], t[1] if t[2] and len(t[2]) > 1 else None) for t in todo for f in fmts}
    output_guard.claim(list(claimed), sources=claimed)     # with their inputs: solve names them alike
    records, failed = list(blocked), len(blocked)
    try:
        log(f"dask dashboard: {client.dashboard_link}")
        st = dataclasses.asdict(settings)
        n = len(todo)
        futures = client.map(convert_task, [t[0] for t in todo], [out_dir] * n,
                             [names[task_key(*t[:2])] for t in todo], [list(fmts)] * n, [st] * n, [model] * n,
                             [options] * n, [t[1] for t in todo], [t[2] for t in todo], pure=False)
        which = {fut.key: t for fut, t in zip(futures, todo)}
        with _open_manifest(out_dir) as man:
            for i, fut in enumerate(as_completed(futures), 1):
                try:
                    rec = fut.result()
                except Exception as exc:      # its worker died (KilledWorker): an error, the others go on
                    p, person, people = which[fut.key]
                    rec = _error_record(p, _lost_task_message(exc), person, people)
                if rec["status"] == "ok":
                    output_guard.record(rec["outputs"], rec["input"],
                                        rec.get("person") if len(rec.get("people") or ()) > 1 else None)
                man.write(json.dumps(rec) + "\n")
                man.flush()
                os.fsync(man.fileno())
                records.append(rec)
                failed += rec["status"] != "ok"
                if report is not None:
                    report(rec)
                if progress:
                    bar = "#" * int(30 * i / len(todo))
                    sys.stderr.write(f"\r[{bar:<30}] {i}/{len(todo)} done: {i - failed} converted, {failed} failed")
                    sys.stderr.flush()
                if rec["status"] != "ok":
                    log(("\n" if progress else "") + f"ERROR {said(rec)}: {rec['error']}")
        if progress:
            sys.stderr.write("\n")
    except KeyboardInterrupt:
        if progress:
            sys.stderr.write("\n")
        log("interrupted (Ctrl-C or a stop signal): " + summary(out_dir, len(records) - failed, failed, skipped,
                                               len(tasks) - skipped - len(records)))
        raise
    finally:
        if cluster is None:           # a --scheduler's workers outlive the run: a group file kept by one
            _forget_on_workers(client)   # (its last person done elsewhere or skipped) is not kept on
        client.close()
        if cluster is not None:
            cluster.close()
    log(summary(out_dir, len(records) - failed, failed, skipped))
    return (0 if failed == 0 else 1), records
