"""Dataset-scale conversion on Dask (core/convert.py, `blender-manikin convert`), without Blender."""
import dataclasses
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import types

import numpy as np
import pytest

pytest.importorskip("distributed")

from blender_manikin.core import convert  # noqa: E402
from blender_manikin.core.export_json import validate_document  # noqa: E402
from blender_manikin.core.output_guard import RECORD  # noqa: E402
from blender_manikin.core.solve import SolveSettings  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def _folder(tmp_path, good=4, broken=True):
    d = tmp_path / "in"
    (d / "sub").mkdir(parents=True)
    for i in range(good):
        shutil.copy(EXAMPLE, (d if i % 2 else d / "sub") / f"take{i}.csv")
    if broken:
        (d / "broken.csv").write_text("time,device,px,py,pz,qw,qx,qy,qz\n0.0,head,1,2\n")
        (d / "sub" / "empty.bsor").write_bytes(b"")
    (d / "notes.md").write_text("not a recording")
    return d


def _manifest_lines(out):
    with open(os.path.join(out, convert.MANIFEST)) as f:
        return [json.loads(ln) for ln in f if ln.strip()]


def test_local_cluster_converts_a_folder_with_broken_files(tmp_path):
    d = _folder(tmp_path)
    inputs = convert.collect_inputs([str(d)])
    assert len(inputs) == 6 and all(os.path.isabs(p) for p in inputs)
    out = str(tmp_path / "out")
    code, records = convert.run(inputs, out, ["json", "npz"], SolveSettings(fps=30.0), workers=2, progress=False,
                                log=lambda m: None)
    assert code == 1 and len(records) == 6
    lines = _manifest_lines(out)
    assert sorted(r["input"] for r in lines) == sorted(inputs)               # one line per input
    ok = [r for r in lines if r["status"] == "ok"]
    bad = {os.path.basename(r["input"]): r["error"] for r in lines if r["status"] != "ok"}
    assert len(ok) == 4 and set(bad) == {"broken.csv", "empty.bsor"}
    assert "broken.csv, line 2" in bad["broken.csv"] and "empty.bsor" in bad["empty.bsor"]
    for r in ok:
        assert r["frames"] == 210 and abs(r["stature"] - 1.75) < 0.05 and r["seconds"] > 0
        js, npz = r["outputs"]
        doc = json.load(open(js))
        assert validate_document(doc) == [] and len(doc["positions"]) == 210
        with np.load(npz) as z:
            assert z["positions"].shape == (210, 22, 3)
    assert not [f for f in os.listdir(out) if ".part" in f]                 # written atomically
    # a rerun converts nothing new and keeps the verdict
    code2, again = convert.run(inputs, out, ["json", "npz"], SolveSettings(fps=30.0), workers=2, progress=False,
                               log=lambda m: None)
    assert code2 == 1 and sorted(os.path.basename(r["input"]) for r in again) == ["broken.csv", "empty.bsor"]


def _wait_for_records(proc, out, n):
    """Wait (at most 120 s) until the running ``proc`` has ``n`` lines in ``out``'s manifest;
    returns the manifest's path."""
    man = out / convert.MANIFEST
    deadline = time.time() + 120
    while time.time() < deadline and proc.poll() is None:
        if man.exists() and len(man.read_text().splitlines()) >= n:
            break
        time.sleep(0.05)
    return man


def _copies_of_the_example(d, n):
    """Folder ``d`` with ``n`` copies of the bundled example, ``t00.csv``...: a batch to stop."""
    d.mkdir()
    for i in range(n):
        shutil.copy(EXAMPLE, d / f"t{i:02d}.csv")
    return d


def test_a_killed_run_resumes_without_missing_or_duplicated_outputs(tmp_path):
    d = _copies_of_the_example(tmp_path / "in", 10)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "blender_manikin", "convert", str(d), "--out", str(out), "--format", "json",
           "--workers", "2", "--no-progress"]
    env = dict(os.environ, PYTHONPATH=ROOT)
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    _wait_for_records(proc, out, 2)
    os.killpg(proc.pid, signal.SIGKILL)                                     # the job and its workers
    proc.wait()
    first = [r["input"] for r in _manifest_lines(out)]
    assert len(first) >= 2
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    lines = _manifest_lines(out)
    ok = [r["input"] for r in lines if r["status"] == "ok"]
    assert sorted(ok) == sorted(str(d / f"t{i:02d}.csv") for i in range(10))     # each exactly once
    assert sorted(n for n in os.listdir(out) if n != RECORD) == \
        sorted([f"t{i:02d}.json" for i in range(10)] + [convert.MANIFEST])
    # the rerun's OK lines on stdout name only what it converted
    redone = [ln.split()[1] for ln in p.stdout.splitlines() if ln.startswith("OK ")]
    assert sorted(redone + first) == sorted(ok)


def test_inputs_from_globs_and_manifests_and_unique_stems(tmp_path):
    d = _folder(tmp_path, broken=False)
    globbed = convert.collect_inputs([str(d / "**" / "take*.csv")])
    assert len(globbed) == 4
    lst = tmp_path / "list.txt"
    lst.write_text(f"# takes\n{d / 'take1.csv'}\nin/sub/take0.csv\n")
    jl = tmp_path / "list.jsonl"
    jl.write_text(json.dumps({"path": str(d / "take3.csv")}) + "\n")
    got = convert.collect_inputs([str(lst), str(jl), str(d / "take1.csv")])
    assert got == [str(d / "take1.csv"), str(d / "sub" / "take0.csv"), str(d / "take3.csv")]
    with pytest.raises(ValueError, match="nothing_here"):
        convert.collect_inputs([str(tmp_path / "nothing_here*.csv")])
    bad = tmp_path / "bad.jsonl"
    bad.write_text("{}\n")
    with pytest.raises(ValueError, match="bad.jsonl, line 1"):
        convert.collect_inputs([str(bad)])
    stems = convert.output_stems(["/a/x.csv", "/b/x.csv", "/a/y.csv"])
    assert stems["/a/y.csv"] == "y" and stems["/a/x.csv"] != stems["/b/x.csv"]
    assert all(s.startswith("x-") for k, s in stems.items() if k.endswith("x.csv"))


def test_convert_never_replaces_a_file_the_user_made(tmp_path):
    """An output whose name a file of the user's own already has stops that input (an error in
    the manifest naming the file, the file left as it was); the other inputs convert;
    --overwrite (``options.overwrite``) replaces it."""
    d = tmp_path / "in"
    d.mkdir()
    for n in ("walk", "run"):
        shutil.copy(EXAMPLE, d / f"{n}.csv")
    out = tmp_path / "out"
    out.mkdir()
    (out / "walk.json").write_text("my notes on the walk")
    inputs = convert.collect_inputs([str(d)])
    code, records = convert.run(inputs, str(out), ["json"], SolveSettings(fps=30.0), workers=1, progress=False,
                                log=lambda m: None)
    by = {os.path.basename(r["input"]): r for r in records}
    assert code == 1 and by["run.csv"]["status"] == "ok" and by["walk.csv"]["status"] == "error"
    assert "walk.json already exists" in by["walk.csv"]["error"] and "--overwrite" in by["walk.csv"]["error"]
    assert (out / "walk.json").read_text() == "my notes on the walk"
    code, records = convert.run(inputs, str(out), ["json"], SolveSettings(fps=30.0), workers=1, progress=False,
                                log=lambda m: None, options=types.SimpleNamespace(overwrite=True))
    assert code == 0 and [os.path.basename(r["input"]) for r in records] == ["walk.csv"]
    assert validate_document(json.loads((out / "walk.json").read_text())) == []


def test_convert_refuses_blender_formats(tmp_path):
    with pytest.raises(ValueError, match="not blend"):
        convert.run([EXAMPLE], str(tmp_path), ["blend"], SolveSettings(), progress=False, log=lambda m: None)


def test_convert_refuses_glb_as_a_blender_format(tmp_path, capsys):
    """``convert --format glb``: glTF binary is written by Blender's exporter, so convert (no
    Blender) refuses it by name, nothing written.  Before: 'unknown format(s) glb'."""
    from blender_manikin import cli
    assert cli.main(["convert", EXAMPLE, "--out", str(tmp_path / "out"), "--format", "glb"]) == 2
    err = capsys.readouterr().err
    assert "(without Blender); not glb" in err and "unknown format" not in err
    assert not os.path.exists(tmp_path / "out")


def test_partial_outputs_of_a_killed_run_are_removed_and_nothing_else(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    partial = [".t00.part123.json", ".t01.part9.bvh", ".t02.part77.json.tmp", ".t03.part5.npz.tmp.npz"]
    kept = ["t00.json", ".keep", "notes.txt", ".t04.json", "t05.part1.json"]
    for name in partial + kept:
        (out / name).write_text("x")
    assert convert.remove_partial_outputs(out) == len(partial)
    assert sorted(os.listdir(out)) == sorted(kept)


def test_a_rerun_writes_new_formats_and_never_reuses_an_earlier_inputs_name(tmp_path, monkeypatch):
    """Reruns into one --out: more formats asked for are written (not skipped as converted), a take
    named as an earlier run's gets a name of its own (the earlier outputs stay), and the manifest's
    outputs are found from whichever folder the rerun starts in."""
    a, b = tmp_path / "a" / "take.csv", tmp_path / "b" / "take.csv"
    for p in (a, b):
        p.parent.mkdir()
        shutil.copy(EXAMPLE, p)
    here = tmp_path / "here"
    here.mkdir()
    monkeypatch.chdir(here)

    def run(inputs, fmts):
        return convert.run([str(p) for p in inputs], "out", fmts, SolveSettings(fps=30.0), workers=1,
                           progress=False, log=lambda m: None)

    assert run([a], ["json"])[0] == 0
    first = (here / "out" / "take.json").read_bytes()
    code, recs = run([a], ["json", "npz"])
    assert code == 0 and len(recs) == 1 and (here / "out" / "take.npz").is_file()
    code, recs = run([b], ["json"])
    assert code == 0 and recs[0]["outputs"] != [str(here / "out" / "take.json")]
    assert (here / "out" / "take.json").read_bytes() == first and os.path.isfile(recs[0]["outputs"][0])
    monkeypatch.chdir(tmp_path)
    code, recs = convert.run([str(a), str(b)], str(here / "out"), ["json"], SolveSettings(fps=30.0), workers=1,
                             progress=False, log=lambda m: None)
    assert code == 0 and recs == []


def test_output_stems_unique_on_case_insensitive_disks():
    """``Take.csv`` and ``take.csv`` (and ``Übung`` composed / decomposed) are one file name on
    Windows and macOS: their outputs must not share a name there (they did: ``Take.bvh`` and
    ``take.bvh``, one over the other)."""
    import unicodedata
    nfc, nfd = unicodedata.normalize("NFC", "Übung 1"), unicodedata.normalize("NFD", "Übung 1")
    paths = ["/in/Take.csv", "/in/take.csv", f"/in/{nfc}.csv", f"/in/x/{nfd}.csv", "/in/walk.csv"]
    stems = convert.output_stems(paths)
    folded = [unicodedata.normalize("NFC", s).casefold() for s in stems.values()]
    assert len(set(folded)) == len(paths)
    assert stems["/in/walk.csv"] == "walk"
    assert stems["/in/Take.csv"].startswith("Take-") and stems["/in/take.csv"].startswith("take-")


def test_a_long_input_name_gives_outputs_the_disk_takes(tmp_path):
    """An input whose name is 255 bytes (85 Japanese characters: the most ext4 / APFS allow)
    failed with "[Errno 36] File name too long": its output plus ``.tmp`` was 256 bytes.  The
    stem is cut at a character boundary and given the input's hash, so two such inputs that
    share their first characters stay apart."""
    from blender_manikin import cli
    from blender_manikin.core.file_names import MAX_STEM_BYTES
    from fixtures_recordings import write_recording_csv
    names = ["テ" * 83 + "ab", "テ" * 83 + "cd"]
    (tmp_path / "in").mkdir()
    for n in names:
        write_recording_csv(tmp_path / "in", n + ".csv", duration=2.0)
        assert len((n + ".csv").encode()) == 255
    assert cli.main(["solve", str(tmp_path / "in"), "--out", str(tmp_path / "out"), "--format", "json,bvh,npz"]) == 0
    out = sorted(os.listdir(tmp_path / "out"))
    stems = {os.path.splitext(f)[0] for f in out if not f.startswith(".")}
    assert len(stems) == 2 and all(len(s.encode()) <= MAX_STEM_BYTES + 9 for s in stems)
    assert all(s.startswith("テ" * 66) for s in stems)
    assert sum(f.endswith((".json", ".bvh", ".npz")) for f in out) == 6


def test_a_rerun_converts_a_replaced_input_again_and_survives_a_cut_manifest_line(tmp_path):
    """An input replaced since it was converted (same name, new content) is converted again,
    not skipped; a last manifest line a crash cut off (no newline) neither breaks the rerun nor
    swallows the record written after it."""
    d = tmp_path / "in"
    d.mkdir()
    for n in ("a", "b"):
        shutil.copy(EXAMPLE, d / f"{n}.csv")
    out = tmp_path / "out"

    def run():
        return convert.run(convert.collect_inputs([str(d)]), str(out), ["npz"], SolveSettings(fps=30.0),
                           workers=1, progress=False, log=lambda m: None)

    assert run()[0] == 0
    with np.load(out / "a.npz") as z:
        assert z["positions"].shape[0] == 210
    lines = (d / "a.csv").read_text().splitlines(True)
    (d / "a.csv").write_text("".join(lines[:700]))                 # a shorter take under the same name
    code, recs = run()
    assert code == 0 and [os.path.basename(r["input"]) for r in recs] == ["a.csv"]
    with np.load(out / "a.npz") as z:
        frames = z["positions"].shape[0]
    assert frames < 210 and recs[0]["frames"] == frames
    assert run()[1] == []                                            # and then it is done
    # a crash cut b.csv's record mid-write (the last line, no newline): b.csv is redone once, then done
    man = out / convert.MANIFEST
    kept = [ln for ln in man.read_text().splitlines(True) if not ln.startswith('{"input": "' + str(d / "b.csv"))]
    man.write_text("".join(kept) + '{"input": "' + str(d / "b.csv") + '", "sta')
    code, recs = run()
    assert code == 0 and [os.path.basename(r["input"]) for r in recs] == ["b.csv"]
    assert run()[1] == []
    assert sum(r["input"].endswith("b.csv") and r["status"] == "ok" for r in convert.read_manifest(out).values()) == 1


def test_an_output_folder_inside_the_input_folder_is_not_read_as_inputs(tmp_path):
    """``convert in --out in/out``: the rerun finds nothing to do (its .npz outputs are not
    taken for keypoint inputs), and the exit code stays 0."""
    d = tmp_path / "in"
    d.mkdir()
    shutil.copy(EXAMPLE, d / "take.csv")
    cmd = [sys.executable, "-m", "blender_manikin", "convert", str(d), "--out", str(d / "out"), "--format",
           "json,npz", "--workers", "1", "--no-progress"]
    env = dict(os.environ, PYTHONPATH=ROOT)
    for _ in range(2):
        p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
    assert [r["input"] for r in _manifest_lines(d / "out")] == [str(d / "take.csv")]
    assert convert.collect_inputs([str(d), str(d / "**" / "*.npz")], exclude=[str(d / "out")]) == [str(d / "take.csv")]


_REAL_TASK = convert.convert_task


def _task_whose_worker_dies(path, *args, **kwargs):
    """convert_task, except that an input named ``die*`` kills its worker (as the OOM killer would)."""
    if os.path.basename(path).startswith("die"):
        os.kill(os.getpid(), signal.SIGKILL)
    return _REAL_TASK(path, *args, **kwargs)


def test_a_worker_that_dies_makes_its_input_an_error_not_a_crash(tmp_path, monkeypatch):
    d = tmp_path / "in"
    d.mkdir()
    for n in ("a", "die", "z"):
        shutil.copy(EXAMPLE, d / f"{n}.csv")
    monkeypatch.setattr(convert, "convert_task", _task_whose_worker_dies)
    logged = []
    t = time.perf_counter()
    code, records = convert.run(convert.collect_inputs([str(d)]), str(tmp_path / "out"), ["json"],
                                SolveSettings(fps=30.0), workers=1, progress=False, log=logged.append)
    assert time.perf_counter() - t < 120
    by = {os.path.basename(r["input"]): r for r in records}
    assert code == 1 and by["a.csv"]["status"] == by["z.csv"]["status"] == "ok"     # only its own input
    assert by["die.csv"]["status"] == "error" and "worker" in by["die.csv"]["error"]
    assert [r["status"] for r in _manifest_lines(tmp_path / "out")].count("error") == 1
    assert logged[-1] == ("2 converted, 1 error(s), 0 skipped (converted before); manifest: "
                          + str(tmp_path / "out" / convert.MANIFEST))


def test_an_unreachable_scheduler_is_a_clear_error_in_bounded_time(tmp_path):
    env = dict(os.environ, PYTHONPATH=ROOT, DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT="2s")
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "blender_manikin", "convert", EXAMPLE, "--out", str(tmp_path / "out"),
                        "--scheduler", "tcp://127.0.0.1:9", "--no-progress"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=120)
    assert time.perf_counter() - t < 60
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:9 within 2 s" in p.stderr


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_ctrl_c_or_sigterm_stops_the_run_with_a_summary_and_exit_code(tmp_path, sig, code):
    """Ctrl-C in a terminal (the whole process group), or SIGTERM from a job scheduler (the main
    process: it died at once, without a word and with its workers left to the OS)."""
    d = _copies_of_the_example(tmp_path / "in", 40)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "blender_manikin", "convert", str(d), "--out", str(out),
                             "--workers", "2", "--no-progress"], cwd=ROOT, env=dict(os.environ, PYTHONPATH=ROOT),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    man = _wait_for_records(proc, out, 2)
    if sig == signal.SIGINT:
        os.killpg(proc.pid, signal.SIGINT)                   # Ctrl-C in a terminal: the whole group
    else:
        os.kill(proc.pid, signal.SIGTERM)
    so, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert "Traceback" not in err, err
    last = [ln for ln in err.splitlines() if ln.startswith("interrupted (Ctrl-C or a stop signal): ")][-1]
    assert last.endswith(f"manifest: {man}") and "not converted (interrupted)" in last
    ok = sorted(r["input"] for r in _manifest_lines(out) if r["status"] == "ok")
    assert ok and sorted(ln.split()[1] for ln in so.splitlines() if ln.startswith("OK ")) == ok   # as they finished


def test_the_progress_line_counts_converted_and_failed_apart(tmp_path, capsys):
    """The progress bar's figures agree with the summary: one good and one broken input end at
    "2/2 done: 1 converted, 1 failed" (it said "2/2 converted, 1 failed", two converted where one
    was, the last line then "1 converted, 1 error(s)")."""
    d = tmp_path / "in"
    d.mkdir()
    shutil.copy(EXAMPLE, d / "take.csv")
    (d / "broken.csv").write_text("time,device,px,py,pz,qw,qx,qy,qz\n0.0,head,1,2\n")
    inputs = convert.collect_inputs([str(d)])
    code, records = convert.run(inputs, str(tmp_path / "out"), ["json"], SolveSettings(fps=30.0), workers=1,
                                progress=True, log=lambda m: None)
    assert code == 1 and sorted(r["status"] for r in records) == ["error", "ok"]
    bars = [part for part in capsys.readouterr().err.replace("\n", "\r").split("\r") if part.startswith("[")]
    assert bars[-1].endswith("] 2/2 done: 1 converted, 1 failed"), bars


def test_a_file_with_several_people_is_one_task_per_person_and_resumes_per_person(tmp_path):
    """A keypoint array with three people: one output per person, named as ``solve`` names them
    (``<stem>_p<label>``), one manifest line each (with the person); a rerun skips them all, and
    after one person's output is removed converts that person only."""
    from fixtures_keypoints import hinge_motion, to_y_up
    from blender_manikin.core import keypoint_layouts as kl
    body, pos, world = hinge_motion(frames=90, seed=1)
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    X = np.stack([to_y_up(clean + [1.5 * k, 0.0, 0.0]) for k in range(3)])
    X[1, 60:] = np.nan                               # person 1 leaves after 60 frames
    d = tmp_path / "in"
    d.mkdir()
    np.save(d / "group.npy", X)
    shutil.copy(EXAMPLE, d / "take.csv")             # and a tracker take beside it, as before
    out = tmp_path / "out"

    def run():
        return convert.run(convert.collect_inputs([str(d)]), str(out), ["json"], SolveSettings(fps=30.0),
                           workers=1, progress=False, log=lambda m: None)

    code, recs = run()
    assert code == 0, [r["error"] for r in recs]
    assert sorted(n for n in os.listdir(out) if n.endswith(".json")) == [
        "group_p0.json", "group_p1.json", "group_p2.json", "take.json"]
    group = sorted((r for r in _manifest_lines(out) if r["input"].endswith("group.npy")), key=lambda r: r["person"])
    assert [(r["person"], r["people"], r["frames"]) for r in group] == [
        ("0", ["0", "1", "2"], 90), ("1", ["0", "1", "2"], 60), ("2", ["0", "1", "2"], 90)]
    assert len(json.loads((out / "group_p1.json").read_text())["positions"]) == 60
    assert run()[1] == []                                            # all done: nothing converted
    os.remove(out / "group_p1.json")
    code, recs = run()
    assert code == 0 and [(os.path.basename(r["input"]), r["person"]) for r in recs] == [("group.npy", "1")]
    assert (out / "group_p1.json").is_file()
    assert run()[1] == []



def test_convert_dry_run_prints_the_names_and_writes_nothing(tmp_path, capsys):
    """``convert --dry-run``: ``INPUT -> OUTPUTS`` per input (one converted before: its outputs,
    skipped), an input the output guard would refuse an ERROR and exit 1; nothing written, not
    even the folder, the manifest or the record."""
    from blender_manikin import cli
    from blender_manikin.core.file_names import short_hash
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        shutil.copy(EXAMPLE, tmp_path / sub / "take.csv")
    a, b = str(tmp_path / "a" / "take.csv"), str(tmp_path / "b" / "take.csv")
    out = tmp_path / "out"
    opts = ["--out", str(out), "--workers", "1", "--no-progress"]
    assert cli.main(["convert", a, b, *opts, "--dry-run"]) == 0 and not out.exists()
    hashed = {p: str(out / f"take-{short_hash(p)}.json") for p in (a, b)}
    assert capsys.readouterr().out.splitlines() == [f"{a} -> {hashed[a]}", f"{b} -> {hashed[b]}"]
    assert cli.main(["convert", a, *opts]) == 0                         # a alone: take.json
    capsys.readouterr()

    def folder():
        return {n: (out / n).read_bytes() for n in os.listdir(out)}
    seen = folder()
    assert cli.main(["convert", a, b, *opts, "--dry-run"]) == 0
    assert capsys.readouterr().out.splitlines() == [f"{a} -> {out / 'take.json'} (converted before: skipped)",
                                                    f"{b} -> {hashed[b]}"]
    assert folder() == seen
    with open(hashed[b], "w") as f:                                     # a file of the user's own: in the way
        f.write("mine")
    seen = folder()
    assert cli.main(["convert", a, b, *opts, "--dry-run"]) == 1
    cap = capsys.readouterr()
    assert f"ERROR {b}: {hashed[b]} already exists" in cap.err
    assert cap.out.splitlines() == [f"{a} -> {out / 'take.json'} (converted before: skipped)"]
    assert folder() == seen


def test_convert_keeps_an_inputs_name_when_a_namesake_joins_the_batch(tmp_path):
    """``a/take.csv`` converted alone writes ``take.json``; converted again with another format
    beside ``b/take.csv`` it still writes ``take.json`` and ``take.bvh`` (it wrote
    ``take-<hash>.*``, leaving a stale ``take.json``), and ``b`` gets ``take-<hash>``."""
    from blender_manikin.core.file_names import short_hash
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        shutil.copy(EXAMPLE, tmp_path / sub / "take.csv")
    a, b = str(tmp_path / "a" / "take.csv"), str(tmp_path / "b" / "take.csv")
    out = tmp_path / "out"
    run = dict(workers=1, progress=False, log=lambda m: None)
    assert convert.run([a], str(out), ["json"], SolveSettings(fps=30.0), **run)[0] == 0
    assert convert.run([a, b], str(out), ["json", "bvh"], SolveSettings(fps=30.0), **run)[0] == 0
    hb = f"take-{short_hash(b)}"
    assert sorted(n for n in os.listdir(out) if n.endswith((".json", ".bvh"))) == sorted(
        ["take.json", "take.bvh", f"{hb}.json", f"{hb}.bvh"])


def test_solve_into_a_convert_folder_keeps_converts_names(tmp_path):
    """The output record names each output's input, whichever command wrote it: ``solve a/take.csv``
    into a folder ``convert`` wrote ``a`` and ``b``'s ``take-<hash>`` into writes ``take-<hash>``
    again, not a ``take.json`` beside it."""
    from blender_manikin import cli
    from blender_manikin.core.file_names import short_hash
    for sub in ("a", "b"):
        (tmp_path / sub).mkdir()
        shutil.copy(EXAMPLE, tmp_path / sub / "take.csv")
    a, b = str(tmp_path / "a" / "take.csv"), str(tmp_path / "b" / "take.csv")
    out = tmp_path / "out"
    assert convert.run([a, b], str(out), ["json"], SolveSettings(fps=30.0), workers=1, progress=False,
                       log=lambda m: None)[0] == 0
    assert cli.main(["solve", a, "--out", str(out), "--format", "json"]) == 0
    assert sorted(n for n in os.listdir(out) if n.endswith(".json")) == sorted(
        [f"take-{short_hash(a)}.json", f"take-{short_hash(b)}.json"])


def test_a_group_file_is_parsed_once_per_worker_not_once_per_person(tmp_path, monkeypatch):
    """What a worker does with a three-person file's tasks (people_tasks plans them, convert_task
    solves each): the file is parsed once to list the people and once more for all three (it was
    parsed again for each person: four times); each person's output is the one a fresh parse
    gives, one person's failure leaves the others converted, and another file's task drops the
    kept one."""
    from fixtures_keypoints import hinge_motion, to_y_up
    from blender_manikin.core import io_keypoints, keypoint_layouts as kl
    body, pos, world = hinge_motion(frames=90, seed=1)
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    X = np.stack([to_y_up(clean + [1.5 * k, 0.0, 0.0]) for k in range(3)])
    X[1, 60:] = np.nan                               # person 1 leaves after 60 frames
    np.save(tmp_path / "group.npy", X)
    path = str(tmp_path / "group.npy")
    parses, real = [], io_keypoints._load_npy
    monkeypatch.setattr(io_keypoints, "_load_npy", lambda p, *a, **k: parses.append(p) or real(p, *a, **k))
    io_keypoints.forget_loads()
    settings = SolveSettings(fps=30.0)
    tasks = convert.people_tasks([path], settings)
    assert [t[1] for t in tasks] == ["0", "1", "2"] and len(parses) == 1
    st = dataclasses.asdict(settings)
    outs = {}
    for kept in (True, False):
        out = tmp_path / f"out_{kept}"
        out.mkdir()
        recs = []
        for p, person, people in tasks:
            if not kept:
                io_keypoints.forget_loads()          # as if each person ran on a worker of its own
            recs.append(convert.convert_task(p, str(out), f"group_p{person}", ["json"], st, person=person,
                                             people=people))
        assert [(r["status"], r["person"], r["frames"]) for r in recs] == [("ok", "0", 90), ("ok", "1", 60),
                                                                           ("ok", "2", 90)]
        outs[kept] = {n: json.loads((out / n).read_text())["positions"] for n in sorted(os.listdir(out))}
        assert len(parses) == (2 if kept else 5)
        assert io_keypoints._KEPT == {}              # dropped after the file's last person
    assert outs[True] == outs[False]
    # one person failing (a label not in the file) leaves the next converted, from the kept parse
    bad = convert.convert_task(path, str(tmp_path / "out_True"), "group_p9", ["json"], st, person="9",
                               people=["0", "1", "2"])
    assert bad["status"] == "error" and "no such person" in bad["error"]
    ok = convert.convert_task(path, str(tmp_path / "out_True"), "group_p0", ["json"], st, person="0",
                              people=["0", "1", "2"])
    assert ok["status"] == "ok" and len(parses) == 6
    convert.convert_task(EXAMPLE, str(tmp_path / "out_True"), "take", ["json"], st)
    assert io_keypoints._KEPT == {}                  # a one-person task drops the group file


def test_a_schedulers_worker_keeps_no_group_file_after_the_run(tmp_path):
    """A --scheduler's workers outlive the run: a worker whose last task was not the file's last
    person (here person 2 was done before and skipped) dropped nothing, so the parse stayed in its
    memory and a rerun after the file was rewritten with the same size and modification time (a
    disk with 1-2 s times) solved the old numbers."""
    from distributed import LocalCluster
    from fixtures_keypoints import hinge_motion, to_y_up
    from blender_manikin.core import io_keypoints, keypoint_layouts as kl
    body, pos, world = hinge_motion(frames=90, seed=1)
    clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
    path, out = str(tmp_path / "group.npy"), str(tmp_path / "out")

    def write(shift):
        np.save(path, np.stack([to_y_up(clean + [1.5 * k + shift, 0.0, 0.0]) for k in range(3)]))
    write(0.0)
    io_keypoints.forget_loads()
    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0")
    try:
        args = ([path], out, ["json"], SolveSettings(fps=30.0))
        kw = dict(scheduler=cluster.scheduler_address, progress=False, log=lambda m: None)
        assert convert.run(*args, **kw)[0] == 0
        for p in ("0", "1"):
            os.remove(os.path.join(out, f"group_p{p}.json"))
        assert [r["person"] for r in convert.run(*args, **kw)[1]] == ["0", "1"]
        assert io_keypoints._KEPT == {}              # the worker (in this process) keeps nothing
        before = json.loads(open(os.path.join(out, "group_p0.json")).read())["positions"]
        mtime = os.stat(path).st_mtime_ns
        write(0.5)                                   # person 0 moved 0.5 m: same size, same time
        os.utime(path, ns=(mtime, mtime))
        os.remove(os.path.join(out, "group_p0.json"))
        assert convert.run(*args, **kw)[0] == 0
        after = json.loads(open(os.path.join(out, "group_p0.json")).read())["positions"]
        assert after != before                       # solved from the file as it is now
    finally:
        cluster.close()
        io_keypoints.forget_loads()
