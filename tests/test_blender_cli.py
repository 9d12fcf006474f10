"""The headless batch converter (cli.py / python -m blender_manikin)."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin import cli  # noqa: E402
from blender_manikin.blender import solve_job  # noqa: E402
from blender_manikin.core import export_json  # noqa: E402
from blender_manikin.core.output_guard import RECORD  # noqa: E402

from blender_util import (BLENDER_BANNER, blender_binary, blender_binary_env, stub_solver, synthetic_result,  # noqa: E402
                          write_recording_csv)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture
def folder(tmp_path):
    d = tmp_path / "in"
    d.mkdir()
    write_recording_csv(d / "walk.csv", synthetic_result(T=30, fps=30.0, seed=1))
    write_recording_csv(d / "wave.csv", synthetic_result(T=20, fps=30.0, seed=2), axes="unity")
    (d / "broken.csv").write_text("time,device,px,py,pz,qw,qx,qy,qz\n0.0,head,1,2\n")
    (d / "notes.txt").write_text("not a recording")
    return d


def test_folder_with_one_broken_file(folder, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    out = tmp_path / "out"
    code = cli.main(["solve", str(folder), "--out", str(out), "--format", "blend,fbx,bvh,json",
                     "--height", "1.8", "--trackers"])
    cap = capsys.readouterr()
    assert code == 1
    ok_lines = [ln for ln in cap.out.splitlines() if ln.startswith("OK ")]
    assert len(cap.out.splitlines()) == 2          # nothing but one line per converted input
    assert sorted(os.path.basename(ln.split()[1]) for ln in ok_lines) == ["walk.csv", "wave.csv"]
    err = [ln for ln in cap.err.splitlines() if ln.strip()]
    assert len(err) == 2 and err[0].startswith("ERROR ") and "broken.csv" in err[0]
    assert err[1] == f"blender_manikin: 2 converted, 1 error(s) of 3 input(s); outputs in {out}"   # the summary
    assert "walk.csv" not in cap.err and "wave.csv" not in cap.err
    for stem, frames in (("walk", 30), ("wave", 20)):
        for ext in ("blend", "fbx", "bvh", "json"):
            assert (out / f"{stem}.{ext}").stat().st_size > 0, (stem, ext)
        doc = json.loads((out / f"{stem}.json").read_text())
        assert export_json.validate_document(doc) == []
        assert len(doc["positions"]) == frames and doc["fps"] == 30.0
        assert doc["source"] == f"{stem}.csv"
        assert set(doc["trackers"]) == {"head", "left_hand", "right_hand"}
    assert not (out / "broken.json").exists()


def test_blend_and_fbx_contents(folder, tmp_path, monkeypatch):
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    out = tmp_path / "out"
    assert cli.main(["solve", str(folder / "walk.csv"), "--out", str(out), "--format", "blend,fbx",
                     "--fps", "30", "--height", "1.8"]) == 0
    bpy.ops.wm.open_mainfile(filepath=str(out / "walk.blend"))
    arms = [o for o in bpy.data.objects if o.type == 'ARMATURE']
    assert len(arms) == 1 and arms[0].animation_data.action.name.startswith("MANIKIN_live")
    assert bpy.context.scene.render.fps == 30 and bpy.context.scene.frame_end == 30
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=str(out / "walk.fbx"))
    arms = [o for o in bpy.data.objects if o.type == 'ARMATURE']
    assert len(arms) == 1 and "left_elbow" in arms[0].data.bones
    assert arms[0].animation_data is not None and arms[0].animation_data.action is not None


def test_usage_errors(tmp_path, capsys):
    assert cli.main(["solve", "x.csv", "--out", str(tmp_path), "--format", "gif"]) == 2
    assert "gif" in capsys.readouterr().err
    assert cli.main(["solve", "--out", str(tmp_path)]) == 2
    assert cli.main(["solve", str(tmp_path / "nothing_here.csv"), "--out", str(tmp_path)]) == 1
    assert "nothing_here.csv" in capsys.readouterr().err


def _run(args, cwd):
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return subprocess.run([sys.executable] + args, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=120)


def test_python_m_and_plain_script(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("garbage\n")
    # python -m blender_manikin (from the repository root)
    p = _run(["-m", "blender_manikin", "solve", str(bad), "--out", str(tmp_path / "o")], ROOT)
    assert p.returncode == 1 and "bad.csv" in p.stderr and p.stdout == ""
    # cli.py as a plain script from elsewhere (what `blender -b --python cli.py -- ...` does)
    p = _run([os.path.join(ROOT, "blender_manikin", "cli.py"), "--", "solve", str(bad), "--out",
              str(tmp_path / "o")], str(tmp_path))
    assert p.returncode == 1 and "ERROR" in p.stderr and "bad.csv" in p.stderr, p.stderr


def test_real_conversion_subprocess(tmp_path):
    """The real pipeline end to end (needs the shipped network)."""
    from blender_manikin.core import model_runner
    assert os.path.isfile(model_runner.DEFAULT_MODEL), "the shipped pose model is missing"
    rec = write_recording_csv(tmp_path / "take.csv", synthetic_result(T=60, fps=30.0))
    p = _run(["-m", "blender_manikin", "solve", str(rec), "--out", str(tmp_path / "o"),
              "--format", "blend,fbx,json", "--height", "1.8"], ROOT)
    assert p.returncode == 0, p.stderr
    assert len(p.stdout.strip().splitlines()) == 1
    doc = json.loads((tmp_path / "o" / "take.json").read_text())
    assert export_json.validate_document(doc) == []


def test_blender_binary(tmp_path):
    """``blender -b --python cli.py -- solve``: a bad input fails with the error on stderr, and
    stdout holds nothing but Blender's own banner."""
    blender, _ = blender_binary()
    bad = tmp_path / "bad.csv"
    bad.write_text("garbage\n")
    p = subprocess.run([blender, "-b", "--factory-startup", "--python",
                        os.path.join(ROOT, "blender_manikin", "cli.py"), "--", "solve", str(bad),
                        "--out", str(tmp_path / "o")], capture_output=True, text=True, timeout=300,
                       env=blender_binary_env())
    assert p.returncode == 1 and "bad.csv" in p.stderr, (p.stdout, p.stderr)
    assert all(BLENDER_BANNER.match(line) for line in p.stdout.splitlines()), p.stdout


def test_offsets_auto_resolution():
    from types import SimpleNamespace as NS
    from blender_manikin.blender.solve_job import resolve_offsets
    assert resolve_offsets("auto", NS(metadata={"offsets": "quest_touch"}, source="a.csv")) == "quest_touch"
    assert resolve_offsets("auto", NS(metadata={"offsets": "no_such"}, source="a.csv")) == "none"
    assert resolve_offsets("auto", NS(metadata={}, source="/x/replay.BSOR")) == "beat_saber"
    assert resolve_offsets("auto", NS(metadata={}, source="a.csv")) == "none"
    assert resolve_offsets("index_knuckles", NS(metadata={"offsets": "quest_touch"}, source="a.csv")) == \
        "index_knuckles"


def test_implausible_stature_is_flagged_in_the_summary(tmp_path, capsys, monkeypatch):
    """A recording whose head stands 1.1 m above its floor (a tracking origin above the floor,
    or a seated performer) gives a 1.2 m body: the per-input line says so and why."""
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    rec = write_recording_csv(tmp_path / "low.csv", synthetic_result(T=30, fps=30.0, stature=1.2))
    assert cli.main(["solve", str(rec), "--out", str(tmp_path / "o"), "--format", "json"]) == 0
    line = capsys.readouterr().out.strip()
    assert "estimated stature 1.20 m is outside 1.40-2.10 m" in line and "floor" in line, line
    # a plausible one says nothing
    rec = write_recording_csv(tmp_path / "ok.csv", synthetic_result(T=30, fps=30.0, stature=1.75))
    assert cli.main(["solve", str(rec), "--out", str(tmp_path / "o"), "--format", "json"]) == 0
    assert "estimated stature" not in capsys.readouterr().out


def test_inputs_named_alike_each_get_their_own_outputs(folder, tmp_path, capsys, monkeypatch):
    """Two takes with one name (walk.csv in two folders, walk.csv beside walk.CSV) are not written
    over one another: each gets its own outputs, told apart by a short hash as `convert` does."""
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    (tmp_path / "b").mkdir()
    other = write_recording_csv(tmp_path / "b" / "walk.csv", synthetic_result(T=25, fps=30.0, seed=3))
    beside = write_recording_csv(folder / "walk.CSV", synthetic_result(T=15, fps=30.0, seed=4))
    out = tmp_path / "out"
    assert cli.main(["solve", str(folder / "walk.csv"), str(other), str(beside), "--out", str(out),
                     "--format", "json,bvh", "--height", "1.8"]) == 0
    written = [ln.split(" -> ")[1].split(" (")[0].split(", ") for ln in capsys.readouterr().out.splitlines()]
    assert len(written) == 3 and len({p for w in written for p in w}) == 6
    assert sorted(n for n in os.listdir(out) if n != RECORD) == sorted(os.path.basename(p) for w in written for p in w)
    frames = sorted(len(json.loads((out / n).read_text())["positions"]) for n in os.listdir(out) if n.endswith(".json"))
    assert frames == [15, 25, 30]
    # a single input keeps its plain name, and a FreeMoCap session solved as "." is named after its folder
    session = tmp_path / "session"
    shutil.copytree(os.path.join(ROOT, "examples", "example_keypoints"), session)
    monkeypatch.chdir(session)
    assert cli.main(["solve", ".", "--out", str(tmp_path / "kp"), "--format", "json"]) == 0
    assert [n for n in os.listdir(tmp_path / "kp") if n != RECORD] == ["session.json"]


def test_outputs_never_replace_a_file_the_user_made_or_changed(tmp_path, capsys):
    """A rerun into the same folder replaces its own earlier outputs; a file of the user's own with
    an output's name, or an output edited since (a .blend an animator opened and saved), stops
    that input with an error naming it and is left as it was; --overwrite replaces them."""
    rec = write_recording_csv(tmp_path / "take.csv", synthetic_result(T=30, fps=30.0, stature=1.75))
    out = tmp_path / "o"
    args = ["solve", str(rec), "--out", str(out), "--format", "json,bvh"]
    assert cli.main(args) == 0
    assert cli.main(args) == 0                          # its own unchanged outputs: replaced
    capsys.readouterr()
    (out / "take.bvh").write_text("the animator's cleaned-up take\n")
    assert cli.main(args) == 1
    err = capsys.readouterr().err
    assert f"ERROR {rec}: {out / 'take.bvh'} already exists" in err and "--overwrite" in err
    assert (out / "take.bvh").read_text() == "the animator's cleaned-up take\n"
    json_before = (out / "take.json").read_bytes()
    assert cli.main(args) == 1 and (out / "take.json").read_bytes() == json_before     # nothing written
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "take.json").write_text("{}")                # the user's own file, never written by the tool
    assert cli.main(["solve", str(rec), "--out", str(mine), "--format", "json"]) == 1
    assert (mine / "take.json").read_text() == "{}"
    assert cli.main(args + ["--overwrite"]) == 0
    assert (out / "take.bvh").read_text().startswith("HIERARCHY")
    assert cli.main(args) == 0                          # recorded again: a plain rerun replaces it
    # --out naming a file is a usage error; a folder without recordings is said
    assert cli.main(["solve", str(rec), "--out", str(rec), "--format", "json"]) == 2
    assert "is a file, not a folder" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert cli.main(["solve", str(tmp_path / "empty"), str(rec), "--out", str(out), "--format", "json"]) == 0
    assert f"{tmp_path / 'empty'}: no recordings in this folder" in capsys.readouterr().err


def test_ctrl_c_stops_the_batch_and_leaves_no_truncated_fbx(folder, tmp_path, capsys, monkeypatch):
    """Ctrl-C while the first take's FBX is written (the exporter writes as it goes, and Blender's
    operator turns the KeyboardInterrupt into an error): the batch stops with 130, the take's
    .fbx is not left truncated under its name, and the next take is not started."""
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    real = cli.export_fbx

    def export_fbx(path, output, preset="blender"):
        real(path, output, preset)
        with open(path, "r+b") as f:           # the exporter's first part is on disk ...
            f.truncate(1000)
        try:
            os.kill(os.getpid(), signal.SIGINT)  # ... when Ctrl-C comes
            time.sleep(1.0)
        except KeyboardInterrupt:
            raise RuntimeError("Error: Python: Traceback (most recent call last):\nKeyboardInterrupt") from None

    monkeypatch.setattr(cli, "export_fbx", export_fbx)
    out = tmp_path / "out"
    code = cli.main(["solve", str(folder / "walk.csv"), str(folder / "wave.csv"), "--out", str(out),
                     "--format", "json,fbx", "--height", "1.8"])
    cap = capsys.readouterr()
    assert code == 130 and cap.out == "" and "interrupted" in cap.err
    # written before the FBX; nothing of wave.csv
    assert [n for n in os.listdir(out) if n != RECORD] == ["walk.json"]


def test_blender_binary_writes_where_it_runs_whatever_pwd_says(tmp_path):
    """A relative --out is the folder the command runs in: a pipeline's subprocess.run(cwd=...) keeps
    its own $PWD, which a Blender binary resolves relative paths against; the .blend and .fbx must
    land beside the JSON, not under $PWD."""
    blender, _ = blender_binary()
    job, stale = tmp_path / "job", tmp_path / "stale"
    (stale / "o").mkdir(parents=True)
    shutil.copytree(os.path.join(ROOT, "examples", "example_keypoints"), job / "take")   # no network needed
    p = subprocess.run([blender, "-b", "--factory-startup", "--python",
                        os.path.join(ROOT, "blender_manikin", "cli.py"), "--", "solve", "take",
                        "--out", "o", "--format", "blend,fbx,json"], cwd=job, capture_output=True, text=True,
                       timeout=300, env=blender_binary_env(PWD=str(stale)))
    assert p.returncode == 0, (p.stdout, p.stderr)
    assert sorted(n for n in os.listdir(job / "o") if n != RECORD) == ["take.blend", "take.fbx", "take.json"]
    assert os.listdir(stale / "o") == []


def test_a_second_run_leaves_no_blend1_backup(folder, tmp_path, capsys, monkeypatch):
    """Solving into the same folder again replaces the tool's own .blend; Blender's Save Versions
    left a walk.blend1 beside it each time (and the user's preference is as it was)."""
    monkeypatch.setattr(solve_job, "run_solver", stub_solver)
    out = tmp_path / "out"
    keep = bpy.context.preferences.filepaths.save_version
    for _ in range(2):
        cli.main(["solve", str(folder / "walk.csv"), "--out", str(out), "--format", "blend", "--height", "1.8"])
    assert "OK " in capsys.readouterr().out
    assert sorted(os.listdir(out)) == sorted(["walk.blend", RECORD])
    assert bpy.context.preferences.filepaths.save_version == keep
