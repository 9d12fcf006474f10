"""The staged solve without Blender (core/solve.py): what the add-on's job and the CLI run."""
import os
import subprocess
import sys

import numpy as np
import pytest

from blender_manikin.core import solve as cs
from blender_manikin.core.formats import load_recording

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def test_solve_recording_runs_every_stage_on_the_example():
    stages = []
    out = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0), progress=lambda f, s=None: stages.append((f, s)))
    res = out.result
    assert res.num_frames == out.targets.num_frames > 100 and res.fps == 30.0
    assert out.recording.source.endswith("example_recording.csv")
    assert out.info[0].startswith("calibrated on a T-pose")
    assert abs(out.body.stature - 1.75) < 0.05
    hands = np.linalg.norm(res.positions[:, 20] - out.targets.pos["left_hand"], axis=-1)
    assert hands.max() < 1e-4
    fr = [f for f, _ in stages]
    assert fr == sorted(fr) and fr[0] == 0.0 and fr[-1] == 1.0
    assert [s for _, s in stages if s][:4] == ["reading recording", "resampling", "calibrating", "solving"]
    assert set(out.timings) >= {"read", "resample", "calibrate", "solve"}
    line = out.summary()
    assert line.startswith(f"{res.num_frames} frames at 30 fps") and "calibrated on a T-pose" in line


def test_a_recording_object_is_solved_the_same_as_its_file():
    a = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0))
    b = cs.solve_recording(load_recording(EXAMPLE), cs.SolveSettings(fps=30.0))
    assert np.array_equal(a.result.local_rot, b.result.local_rot)


def test_the_soles_lift_the_body_and_leave_the_barefoot_stature():
    """The example's performer (1.75 m barefoot) stands on 3 cm soles: calibrated with the
    default soles the stature is 1.75 m; told barefoot, the same head height is a taller body;
    the solved balls of the feet never go through the soles; a typed height stays as typed."""
    rec = load_recording(EXAMPLE)
    shod = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    bare = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, sole=0.0))
    thick = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, sole=0.06))
    assert shod.body.sole == 0.03 and bare.body.sole == 0.0 and thick.body.sole == 0.06
    assert shod.body.stature == pytest.approx(1.75, abs=0.01)
    assert bare.body.stature - shod.body.stature == pytest.approx(0.03 / 0.870, abs=2e-3)
    assert shod.body.stature - thick.body.stature == pytest.approx(0.03 / 0.870, abs=2e-3)
    for out in (shod, bare, thick):
        ball = out.result.positions[:, [10, 11], 2]           # balls of the feet
        assert ball.min() >= out.body.sole - 0.003               # (the solved foot turns a little)
    typed = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, calibration="MEASURE", height=1.8, sole=0.05))
    assert typed.body.stature == 1.8 and typed.body.sole == 0.05
    assert typed.body.rest_positions()[10, 2] == pytest.approx(0.012 * 1.8 + 0.05, abs=1e-9)
    # without a calibration pose: the stature from the standing head height, less the soles
    head_z = np.nanpercentile(shod.targets.pos["head"][:, 2], 90)
    for sole in (None, 0.0):
        b = cs.body_from_head_height(shod.targets, sole=sole)
        assert b.stature == pytest.approx((head_z - (0.03 if sole is None else sole)) / 0.870, abs=1e-9)
    with pytest.raises(cs.SolveError, match="sole"):
        cs.solve_recording(rec, cs.SolveSettings(fps=30.0, sole=0.5))


def test_a_typed_arm_span_is_kept_with_a_t_pose_and_no_typed_height():
    """The panel's Arm Span (or --arm-span) without a typed height: the T-pose gives the stature
    and the typed span is the body's (it was dropped for the T-pose's 1.53 m unless a height was
    typed too)."""
    out = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0, arm_span=1.80))
    assert "calibrated on a T-pose at 0.53 s: stature 1.75 m, arm span 1.80 m" in out.summary()
    with_height = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0, arm_span=1.80, height=1.75))
    assert "arm span 1.80 m" in with_height.summary()
    # the body solved with (its reach margin on the typed span) is the same either way
    assert out.body.measurements.arm_span == pytest.approx(with_height.body.measurements.arm_span)


def test_settings_errors_are_solve_errors():
    with pytest.raises(cs.SolveError, match="no frame rate"):
        cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=None))
    with pytest.raises(cs.SolveError, match="outside the recording"):
        cs.solve_recording(EXAMPLE, cs.SolveSettings(calibration="TPOSE", tpose_time=99.0))
    with pytest.raises(cs.SolveError, match="needs a height"):
        cs.solve_recording(EXAMPLE, cs.SolveSettings(calibration="MEASURE"))
    with pytest.raises(cs.SolveError, match="no recording file"):
        cs.solve_recording("", cs.SolveSettings())


def test_a_cancel_raised_from_progress_stops_the_solve():
    class Stop(Exception):
        pass

    def progress(f, stage=None):
        if stage == "calibrating":
            raise Stop()
    with pytest.raises(Stop):
        cs.solve_recording(EXAMPLE, cs.SolveSettings(), progress=progress)


def test_core_solve_never_imports_bpy():
    code = ("import sys; from blender_manikin.core.solve import solve_recording, SolveSettings; "
            f"solve_recording({EXAMPLE!r}, SolveSettings(fps=30.0)); "
            "print('bpy' in sys.modules, 'blender_manikin.blender' in sys.modules)")
    env = dict(os.environ, PYTHONPATH=ROOT)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.split() == ["False", "False"]


def test_cli_writes_json_and_bvh_without_blender(tmp_path):
    """With bpy unavailable, json and bvh still convert (the core writes them); blend asks for Blender."""
    out = tmp_path / "o"
    code = ("import sys; sys.modules['bpy'] = None; from blender_manikin import cli; "
            f"sys.exit(cli.main(['solve', {EXAMPLE!r}, '--out', {str(out)!r}, '--format', 'json,bvh']))")
    env = dict(os.environ, PYTHONPATH=ROOT)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"OK {EXAMPLE}") and "calibrated on a T-pose" in lines[0]
    assert (out / "example_recording.json").stat().st_size > 0 and (out / "example_recording.bvh").stat().st_size > 0
    code = code.replace("'json,bvh'", "'json,blend'")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)
    assert p.returncode == 2 and "blend needs Blender" in p.stderr and p.stdout == ""


@pytest.mark.parametrize("stride", [40, 33, 100])
def test_network_windows_cover_every_frame_at_any_stride(stride):
    """run_network's stride (frames between windows) up to a whole window, and above it
    clamped to one: every frame gets a prediction."""
    from blender_manikin.core import pipeline
    out = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0))
    from blender_manikin.core.model_runner import load_model
    net = pipeline.run_network(out.targets, out.body, load_model(), stride=stride)
    assert np.isfinite(net.ankle_pos).all() and np.isfinite(net.swivel).all()
    assert net.ankle_pos.shape[0] == out.targets.num_frames


def test_window_blend_weights_rise_from_the_ends_and_reach_the_network(monkeypatch):
    """Overlapping windows blend with the triangle to WINDOW_BLEND_POWER: symmetric, largest at
    the centre, smallest (but not zero) at the ends; power 1 is the triangle itself.  The network
    stage uses them: another power gives another blend, the same power the same one."""
    from blender_manikin.core import pipeline
    from blender_manikin.core.model_runner import load_model
    for W in (40, 60, 61):
        w = pipeline.window_blend_weights(W)
        assert w.shape == (W,) and np.allclose(w, w[::-1]) and (w > 0).all()
        half = w[:(W + 1) // 2]
        assert (np.diff(half) > 0).all() and w.argmax() in (W // 2 - 1, W // 2)
        tri = 1.0 - np.abs((np.arange(W) + 0.5) / W * 2.0 - 1.0)
        assert np.allclose(pipeline.window_blend_weights(W, 1.0), tri + 1e-3)
        assert np.allclose(w, tri ** pipeline.WINDOW_BLEND_POWER + 1e-3)
    assert 0.0 < pipeline.WINDOW_BLEND_POWER < 1.0       # flatter than the triangle (measured better)
    out = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0))
    runner = load_model()
    default = pipeline.run_network(out.targets, out.body, runner)
    power = pipeline.WINDOW_BLEND_POWER
    monkeypatch.setattr(pipeline, "WINDOW_BLEND_POWER", 1.0)
    triangle = pipeline.run_network(out.targets, out.body, runner)
    assert not np.allclose(default.ankle_pos, triangle.ankle_pos)
    monkeypatch.setattr(pipeline, "WINDOW_BLEND_POWER", power)
    assert np.array_equal(default.ankle_pos, pipeline.run_network(out.targets, out.body, runner).ankle_pos)


def test_overlap_sets_how_many_windows_see_each_frame(monkeypatch):
    """overlap N (2, 3, 4): the stride is the model's window / N, for any model's window; the
    solve's setting, the command line's --overlap and the Dask conversion reach the network;
    anything else is refused with what is allowed."""
    from blender_manikin import cli
    from blender_manikin.core import pipeline
    from blender_manikin.core.model_runner import load_model
    out = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0))
    runner = load_model()
    W = runner.contract.window
    two = pipeline.run_network(out.targets, out.body, runner)
    three = pipeline.run_network(out.targets, out.body, runner, overlap=3)
    same = pipeline.run_network(out.targets, out.body, runner, stride=round(W / 3))
    assert np.array_equal(three.ankle_pos, same.ankle_pos) and np.array_equal(three.swivel, same.swivel)
    assert not np.allclose(two.ankle_pos, three.ankle_pos)        # more views of each frame, another average
    assert np.array_equal(two.ankle_pos, pipeline.run_network(out.targets, out.body, runner, overlap=2).ankle_pos)
    seen = []
    real = pipeline.run_network

    def spy(*a, **k):
        seen.append(k.get("overlap"))
        return real(*a, **k)
    monkeypatch.setattr(pipeline, "run_network", spy)
    res = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0, overlap=4)).result
    assert seen and set(seen) == {4} and np.isfinite(res.positions).all()
    for bad in (1, 5, 2.5, "3"):
        with pytest.raises(cs.SolveError, match="choose 2, 3, 4"):
            cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0, overlap=bad))
    p = cli.build_parser()
    assert cli.solve_settings(p.parse_args(["solve", "take.csv", "--out", "o"])).overlap == 2
    assert cli.solve_settings(p.parse_args(["solve", "take.csv", "--out", "o", "--overlap", "3"])).overlap == 3
    assert cli.solve_settings(p.parse_args(["convert", "in", "--out", "o", "--overlap", "4"])).overlap == 4
    with pytest.raises(SystemExit):
        p.parse_args(["solve", "take.csv", "--out", "o", "--overlap", "5"])


def test_command_line_sole_reaches_the_settings():
    from blender_manikin import cli
    p = cli.build_parser()
    assert cli.solve_settings(p.parse_args(["solve", "take.csv", "--out", "o"])).sole is None
    assert cli.solve_settings(p.parse_args(["solve", "take.csv", "--out", "o", "--sole", "0"])).sole == 0.0
    st = cli.solve_settings(p.parse_args(["convert", "in", "--out", "o", "--sole", "0.05"]))
    assert st.sole == 0.05


def _raised(rec, dz):
    """``rec`` with every device moved up by ``dz`` metres (a recording whose floor is at -dz)."""
    import copy
    out = copy.deepcopy(rec)
    for st in out.streams.values():
        st.pos[:, 2] += dz
    return out


def test_the_floor_setting_puts_an_eye_level_origin_on_the_ground():
    """A recording whose origin is at the performer's eyes (an OpenXR LOCAL space: the floor at
    -1.6 m), the floor left at 0: the floor is found under the performer the T-pose's arm span
    gives (1.753 m for the example's 1.75 m); told where the floor is, or to put it under the
    1.75 m performer, it solves as the recording on the floor does."""
    rec = load_recording(EXAMPLE)
    ref = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    assert ref.floor == 0.0 and not any(n.startswith("floor at") for n in ref.info)
    low = _raised(rec, -1.6)
    found = cs.solve_recording(low, cs.SolveSettings(fps=30.0))
    assert found.floor == pytest.approx(-1.6, abs=0.01)
    assert ("(the recording's origin is at eye level: under a 1.75 m performer, from the T-pose's arm span at "
            "0.53 s) moved to 0") in found.summary()
    assert np.abs(found.result.positions - ref.result.positions).max() < 0.02
    # no T-pose to measure (the take from 1.5 s on): a 1.75 m performer, and the summary says so
    for st in low.streams.values():
        keep = st.time >= st.time[0] + 1.5
        st.time, st.pos, st.quat, st.valid = st.time[keep], st.pos[keep], st.quat[keep], st.valid[keep]
    guessed = cs.solve_recording(low, cs.SolveSettings(fps=30.0))
    assert "at eye level: under a 1.75 m performer: no T-pose to measure, type the height" in guessed.summary()
    assert guessed.body.stature == pytest.approx(1.75, abs=0.005)
    low = _raised(rec, -1.6)
    typed = cs.solve_recording(low, cs.SolveSettings(fps=30.0, floor=-1.6))
    assert typed.floor == -1.6 and "floor at -1.600 m (as set) moved to 0" in typed.summary()
    np.testing.assert_allclose(typed.result.positions, ref.result.positions, atol=1e-6)
    np.testing.assert_allclose(typed.targets.pos["head"], ref.targets.pos["head"], atol=1e-9)
    under = cs.solve_recording(low, cs.SolveSettings(fps=30.0, floor="height", height=1.75))
    assert under.floor == pytest.approx(-1.6, abs=0.005)          # the performer is 1.75 m on 3 cm soles
    assert under.info[0].startswith("calibrated on a T-pose")        # the T-pose is found above that floor
    assert "(under the 1.75 m performer) moved to 0" in under.summary()
    assert np.abs(under.result.positions - ref.result.positions).max() < 0.01
    # a floor above the origin: the same, the other way
    high = cs.solve_recording(_raised(rec, 0.4), cs.SolveSettings(fps=30.0, floor="0.4"))
    np.testing.assert_allclose(high.result.positions, ref.result.positions, atol=1e-6)


@pytest.mark.parametrize("units,factor", [("cm", 100.0), ("mm", 1000.0)])
def test_metres_read_in_a_smaller_unit_are_an_error_not_an_eye_level_origin(tmp_path, units, factor):
    """A take in metres read as centimetres (--units cm on a file that is in metres, or a file whose
    units line is wrong) has its head 1.6 cm up: not an origin at eye level (that solved a 1.75 m body
    on a floor put 1.6 m down, its hands at the tracked points' 1/100 scale); the head-height check
    says what the positions look like."""
    from blender_manikin.core.io_csv import write_csv
    rec = load_recording(EXAMPLE)
    path = str(tmp_path / "take.csv")
    write_csv(path, rec, axes="openxr", units="m", metadata={"offsets": "openxr_generic"})
    with pytest.raises(Exception, match=f"scaled down {int(factor)}x; they look like metres already: "
                                        "set Units to Metres \\(--units m\\)"):
        cs.solve_recording(path, cs.SolveSettings(fps=30.0, units=units))
    low = _raised(rec, -1.6)          # a true eye-level origin is still found
    assert cs.eye_level_origin(low, cs.SolveSettings()) and cs.hands_from_head(low) > 0.3


def test_floor_settings_are_checked():
    assert cs.parse_floor(None) == 0.0 and cs.parse_floor("") == 0.0 and cs.parse_floor(" Height ") == "height"
    assert cs.parse_floor("-1.25") == -1.25 and cs.parse_floor(0.3) == 0.3
    for bad in ("floor", "nan", "inf", [1.0]):
        with pytest.raises(cs.SolveError, match="floor"):
            cs.parse_floor(bad)
    with pytest.raises(cs.SolveError, match="floor"):               # before the file is read
        cs.solve_recording("no_such_file.csv", cs.SolveSettings(floor="ground"))
    with pytest.raises(cs.SolveError, match=r"needs their height: give --height METRES"):
        cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0, floor="height"))
    from blender_manikin import cli
    p = cli.build_parser()
    assert cli.solve_settings(p.parse_args(["solve", "take.csv", "--out", "o"])).floor == 0.0
    st = cli.solve_settings(p.parse_args(["solve", "t.csv", "--out", "o", "--floor", "height", "--height", "1.8"]))
    assert st.floor == "height" and st.height == 1.8
    assert cli.solve_settings(p.parse_args(["convert", "in", "--out", "o", "--floor", "-1.5"])).floor == -1.5
    with pytest.raises(SystemExit):
        p.parse_args(["solve", "take.csv", "--out", "o", "--floor", "low"])


def test_a_head_far_from_the_typed_height_is_noted():
    """With a typed height the body hangs from the head wherever it is: a head 30 cm above where
    that performer's head stands (a floor 30 cm below the recording's zero) gets a note naming
    the floor; the recording on its floor gets none."""
    rec = load_recording(EXAMPLE)
    ok = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, calibration="MEASURE", height=1.75))
    assert cs.head_height_note(cs.SolveSettings(height=1.75), ok) is None
    assert not any(n.startswith("head stands") for n in ok.info)
    off = cs.solve_recording(_raised(rec, 0.3), cs.SolveSettings(fps=30.0, calibration="MEASURE", height=1.75))
    note = next(n for n in off.info if n.startswith("head stands"))
    assert "0.30 m higher than a standing 1.75 m performer's (1.55 m)" in note and "floor" in note
    assert note in off.summary()
    assert cs.head_height_note(cs.SolveSettings(), off) is None           # no typed height: sized by the head


def test_the_summary_names_the_offsets_auto_chose(tmp_path):
    """--offsets auto says what it chose and why; a preset the user typed is not repeated back."""
    from fixtures_recordings import synthetic_bsor
    data, _ = synthetic_bsor(n=400, controller="Oculus Touch", hmd="Quest 2")
    path = tmp_path / "quest.bsor"
    path.write_bytes(data)
    out = cs.solve_recording(path, cs.SolveSettings(fps=30.0))
    assert "offsets beat_saber_touch (auto: from the file)" in out.summary()
    out = cs.solve_recording(path, cs.SolveSettings(fps=30.0, offsets="beat_saber"))
    assert "offsets " not in out.summary() and out.offsets["name"].startswith("beat_saber")
    assert cs.offsets_note("auto", "openxr_generic") == "offsets openxr_generic (auto: the format's default)"
    assert cs.offsets_note("auto", "none") is None and cs.offsets_note("quest_touch", "quest_touch") is None


def test_a_trimmed_solve_is_the_whole_take_solve_cut():
    """--start / --end: the part of the take asked for, calibrated on the whole take's T-pose and
    solved with the network's context around the cut: the same poses as the whole solve's."""
    full = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0))
    part = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0, start=2.0, end=5.0))
    assert part.result.num_frames == 91 and part.result.t0 == pytest.approx(full.result.t0 + 2.0)
    assert any(n.startswith("calibrated on a T-pose at 0.53 s") for n in part.info)        # before the cut
    assert "trimmed to 2.00-5.00 s" in part.summary()
    e = np.linalg.norm(part.result.positions - full.result.positions[60:151], axis=-1)
    assert e.max() < 0.01 and np.median(e) < 1e-6
    assert part.result.targets.pos["head"].shape == (91, 3)
    np.testing.assert_allclose(part.result.targets.pos["head"], full.result.targets.pos["head"][60:151])
    tail = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0, start=5.5))
    assert tail.result.num_frames == full.result.num_frames - 165
    for kw, msg in (({"start": 9.0}, "start 9 s is past the recording's end"),
                    ({"start": 3.0, "end": 2.0}, "end 2 s is not after start 3 s"),
                    ({"start": -1.0}, "start -1.0: expected seconds >= 0")):
        with pytest.raises(cs.SolveError, match=msg):
            cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0, **kw))


def test_cli_start_and_end(tmp_path):
    r = subprocess.run([sys.executable, "-m", "blender_manikin", "solve", EXAMPLE, "--out", str(tmp_path),
                        "--format", "json", "--start", "1.5", "--end", "4"], capture_output=True, text=True,
                       cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert "76 frames at 30 fps" in r.stdout and "trimmed to 1.50-4.00 s" in r.stdout
    r = subprocess.run([sys.executable, "-m", "blender_manikin", "solve", EXAMPLE, "--out", str(tmp_path),
                        "--end", "soon"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 2 and "'soon' is not a number of seconds" in r.stderr


def test_the_summary_says_what_reading_repaired_or_left_out(tmp_path):
    """Warnings of the reader and the resampler reach the user (panel, CLI), each once."""
    rec = load_recording(EXAMPLE)
    from blender_manikin.core.io_csv import write_csv
    path = tmp_path / "with_chest.csv"
    write_csv(path, rec)
    lines = path.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if ",head," in ln)
    lines.insert(k + 1, lines[k].replace(",head,", ",chest,"))
    path.write_text("\n".join(lines) + "\n")
    out = cs.solve_recording(path, cs.SolveSettings(fps=30.0))
    s = out.summary()
    assert f"device 'chest': 1 row(s) from line {k + 2} ignored" in s and s.count("device 'chest'") == 1


def test_a_recording_timed_in_milliseconds_solves_at_its_length(tmp_path):
    lines = open(EXAMPLE).read().splitlines()
    k = next(i for i, ln in enumerate(lines) if ln.startswith("time,"))
    rows = [ln.split(",") for ln in lines[k + 1:]]
    path = tmp_path / "ms.csv"
    path.write_text("\n".join(lines[:k + 1] + [",".join([f"{float(r[0]) * 1000:.3f}"] + r[1:]) for r in rows]) + "\n")
    out = cs.solve_recording(path, cs.SolveSettings(fps=30.0))
    assert out.result.num_frames == 210 and "times read as milliseconds: samples every" in out.summary()
    assert any(n.startswith("calibrated on a T-pose at 0.53 s") for n in out.info)


def test_the_summary_says_what_the_calibration_found_wrong_or_missing():
    """The calibration's own notes reach the summary (the command line's OK line, the panel's box):
    the problems of a pose that is not a still T-pose ("calibration: ... hold still"), a take
    without a T-pose ("no T-pose found", the README's table) and a seated take's stature from its
    head height."""
    moving = cs.solve_recording(EXAMPLE, cs.SolveSettings(fps=30.0, calibration="TPOSE", tpose_time=1.3))
    problems = [n for n in moving.info if n.startswith("calibration: ")]
    assert problems and all(p in moving.summary() for p in problems), moving.summary()
    rec = load_recording(EXAMPLE)
    for st in rec.streams.values():
        keep = st.time >= st.time[0] + 1.7
        st.time, st.pos, st.quat, st.valid = st.time[keep], st.pos[keep], st.quat[keep], st.valid[keep]
    none = cs.solve_recording(rec, cs.SolveSettings(fps=30.0))
    assert "no T-pose found: stature from the standing head height" in none.summary()
    seated = cs.solve_recording(rec, cs.SolveSettings(fps=30.0, posture="seated"))
    assert "from the seated head height" in seated.summary(), seated.summary()
