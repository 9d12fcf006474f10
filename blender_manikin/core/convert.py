"""Dataset-scale conversion without Blender, on Dask: one task per recording, on a laptop's
``LocalCluster`` or on a cluster (SLURM/PBS through dask-jobqueue, Kubernetes through
dask-kubernetes: any ``distributed`` scheduler address).

    blender-manikin convert INPUTS... --out DIR --format json,npz,bvh [--scheduler local|ADDRESS]
        [--workers N] [solve options: --fps, --height, --offsets, --axes, --units, ...]

* Inputs: files, folders (their recordings, recursively), globs, or manifest files (``.txt`` /
  ``.lst``: one path a line, ``#`` comments; ``.jsonl``: objects with a ``path``).
* Each worker loads the model once; each input is one task that reads one recording, solves it
  (:func:`.solve.solve_recording`) and writes ``DIR/STEM.<ext>`` per format under a temporary
  name, renamed when complete, so memory per worker is bounded by one recording.
* ``DIR/manifest.jsonl`` gets one line per finished input: status (``ok``/``error``), frames,
  seconds, stature, quality notes, outputs, and the error.  A rerun skips the inputs already
  converted (every output present, one in each format asked for), so a crashed or killed job
  resumes where it stopped, and a rerun with more formats writes them; a bad
  file never stops the others.  The exit code is 0 only when every input converted.

Needs the ``[dask]`` extra (``dask[distributed]``); no bpy.
"""
from __future__ import annotations

import glob
import hashlib
import json
import os
import re
import sys
import time

from . import formats, output_guard
from .file_names import fit_bytes, fold
from .solve import SolveSettings, error_message, solve_recording

MANIFEST = "manifest.jsonl"
_MANIFEST_SUFFIXES = (".txt", ".lst", ".jsonl")


# --------------------------------------------------------------------------
# inputs and outputs
def _is_recording(path):
    return formats.is_recording_file(path)


def collect_inputs(items):
    """Absolute paths of the recordings named by ``items`` (files, folders, globs, manifests),
    in order, without duplicates.  Raises ``ValueError`` naming an item that gives nothing."""
    out = []
    for item in items:
        item = os.path.expanduser(str(item))
        if os.path.isdir(item):
            found = sorted(_walk_recordings(item))
        elif os.path.isfile(item) and item.lower().endswith(_MANIFEST_SUFFIXES) and not _is_recording(item):
            found = _read_manifest_file(item)
        elif os.path.isfile(item):
            found = [item]
        else:
            found = sorted(glob.glob(item, recursive=True))
            if not found:
                raise ValueError(f"{item}: no such file, folder or matching files")
        out.extend(os.path.abspath(p) for p in found)
    return list(dict.fromkeys(out))


def _walk_recordings(folder):
    """Recordings under ``folder``: files with a reader's extension, and FreeMoCap recording
    folders (one input each; their own arrays are not inputs)."""
    from .io_keypoints import freemocap_body_file
    for d, dirs, fs in os.walk(folder):
        if freemocap_body_file(d):
            dirs[:] = []
            yield d
            continue
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


def output_stems(paths):
    """``{input: output stem}``: the file (or FreeMoCap folder) name without extension, made unique
    with a short hash of the input's absolute path when two inputs share a name (in different
    folders, or side by side with different extensions: ``take.csv`` and ``take.bsor``).  Names
    are compared as Windows and macOS compare file names (:func:`.file_names.fold`: ``Take.csv``
    and ``take.csv``; ``Übung`` composed and decomposed), so an output folder on such a disk (or
    shared with one) never gets one output over another.  A name longer than
    :data:`.file_names.MAX_STEM_BYTES` (UTF-8) is cut there and given the hash too: a file
    system's 255-byte names must hold the stem, the extension and the temporary ``.part``
    suffix the output is written under first."""
    stems = {p: os.path.splitext(os.path.basename(os.path.abspath(p)))[0] for p in paths}
    counts = {}
    for s in stems.values():
        counts[fold(s)] = counts.get(fold(s), 0) + 1

    def stem(p, s):
        short = fit_bytes(s)
        if counts[fold(s)] == 1 and short == s:
            return s
        return f"{short}-{hashlib.sha1(os.path.abspath(p).encode('utf-8', 'surrogateescape')).hexdigest()[:8]}"
    return {p: stem(p, s) for p, s in stems.items()}


def read_manifest(out_dir):
    """The records of ``DIR/manifest.jsonl`` (last record per input wins); ``{}`` when absent.
    A line cut off by a crash is ignored."""
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
                    records[rec["input"]] = rec
    return records


def is_done(record, fmts=()):
    """Whether ``record`` converted its input, every output is present, and one is in each of ``fmts``."""
    outputs = record.get("outputs", []) if record else []
    return (bool(record) and record.get("status") == "ok" and all(os.path.isfile(p) for p in outputs)
            and all(any(p.endswith(formats.WRITERS[f].extension) for p in outputs) for f in fmts))


# --------------------------------------------------------------------------
# one task (runs on a worker)
def convert_task(path, out_dir, stem, fmts, settings, model=None, options=None):
    """Convert one recording; returns its manifest record (never raises for a bad file)."""
    from . import model_choice, pipeline
    t0 = time.perf_counter()
    rec = {"input": path, "status": "error", "outputs": [], "frames": 0, "seconds": 0.0, "stature": None,
           "notes": [], "error": None}
    try:
        st = SolveSettings(**settings)
        spec = model if model is not None else st.model

        def solver(targets, body, progress=None):
            # one onnxruntime thread per worker; each worker loads a model once (load_model's cache)
            plan = model_choice.plan_models(targets, spec, threads=1)
            return pipeline.solve(targets, body, plan, progress=progress, overlap=st.overlap)

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
    rec["seconds"] = round(time.perf_counter() - t0, 3)
    return rec


# --------------------------------------------------------------------------
def _client(scheduler, workers):
    from distributed import Client, LocalCluster
    if scheduler in (None, "", "local"):
        n = int(workers or os.cpu_count() or 1)
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0")
        return Client(cluster), cluster
    return Client(scheduler), None


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
        progress=True, log=None):
    """Convert ``inputs`` (paths) into ``out_dir``; returns ``(exit code, records of this run)``."""
    import dataclasses
    from distributed import as_completed
    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    bad = [f for f in fmts if f not in formats.WRITERS or formats.WRITERS[f].needs_blender]
    if bad:
        raise ValueError(f"convert writes {', '.join(n for n, w in formats.WRITERS.items() if not w.needs_blender)}"
                         f" (without Blender); not {', '.join(bad)}")
    out_dir = os.path.abspath(out_dir)       # the manifest's outputs hold wherever a rerun starts
    os.makedirs(out_dir, exist_ok=True)
    removed = remove_partial_outputs(out_dir)
    if removed:
        log(f"removed {removed} partial output(s) a killed run left in {out_dir}")
    done = read_manifest(out_dir)
    # the names of earlier runs' inputs count too: a later take.csv never writes over an earlier one's
    stems = output_stems(list(dict.fromkeys(list(inputs) + list(done))))
    todo = [p for p in inputs if not is_done(done.get(p), fmts)]
    skipped = len(inputs) - len(todo)
    if skipped:
        log(f"{skipped} of {len(inputs)} input(s) already converted (manifest): skipped")
    # an output that would replace a file the user made or changed stops its input (output_guard)
    blocked = []
    for p in todo:
        try:
            output_guard.check_free([os.path.join(out_dir, stems[p] + formats.WRITERS[f].extension) for f in fmts],
                                    bool(getattr(options, "overwrite", False)))
        except output_guard.OutputInTheWay as exc:
            blocked.append({"input": p, "status": "error", "outputs": [], "frames": 0, "seconds": 0.0,
                            "stature": None, "notes": [], "error": str(exc)})
    if blocked:
        gone = {r["input"] for r in blocked}
        todo = [p for p in todo if p not in gone]
        with open(os.path.join(out_dir, MANIFEST), "a", encoding="utf-8") as man:
            for rec in blocked:
                man.write(json.dumps(rec) + "\n")
                log(f"ERROR {rec['input']}: {rec['error']}")
    if not todo:
        return 0 if all(is_done(done.get(p), fmts) for p in inputs) else 1, blocked
    # claimed before they are written: what a killed run leaves under these names is replaceable
    output_guard.claim([os.path.join(out_dir, stems[p] + formats.WRITERS[f].extension) for p in todo for f in fmts])
    client, cluster = _client(scheduler, workers)
    try:
        log(f"dask dashboard: {client.dashboard_link}")
        st = dataclasses.asdict(settings)
        futures = client.map(convert_task, todo, [out_dir] * len(todo), [stems[p] for p in todo],
                             [list(fmts)] * len(todo), [st] * len(todo), [model] * len(todo),
                             [options] * len(todo), pure=False)
        records, failed = list(blocked), len(blocked)
        with open(os.path.join(out_dir, MANIFEST), "a", encoding="utf-8") as man:
            for i, fut in enumerate(as_completed(futures), 1):
                rec = fut.result()
                if rec["status"] == "ok":
                    output_guard.record(rec["outputs"])
                man.write(json.dumps(rec) + "\n")
                man.flush()
                os.fsync(man.fileno())
                records.append(rec)
                failed += rec["status"] != "ok"
                if progress:
                    bar = "#" * int(30 * i / len(todo))
                    sys.stderr.write(f"\r[{bar:<30}] {i}/{len(todo)} converted, {failed} failed")
                    sys.stderr.flush()
                if rec["status"] != "ok":
                    log(("\n" if progress else "") + f"ERROR {rec['input']}: {rec['error']}")
        if progress:
            sys.stderr.write("\n")
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return (0 if failed == 0 else 1), records
