"""The headless batch converter (cli.py / python -m blender_manikin)."""
import json
import os
import subprocess
import sys

import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin import cli  # noqa: E402
from blender_manikin.blender import solve_job  # noqa: E402
from blender_manikin.core import export_json  # noqa: E402

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
    assert len(err) == 1 and err[0].startswith("ERROR ") and "broken.csv" in err[0]
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
