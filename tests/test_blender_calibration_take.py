"""The panel's Calibration Take: Find T-Pose looks in it, the solve of a take without a T-pose is
calibrated on it; and the command line's --calibration-take."""
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.core.io_csv import write_csv  # noqa: E402

from fixtures_six_trackers import body_with_legs, random_mounts, six_tracker_recording  # noqa: E402
from test_calibration_take import without_tpose  # noqa: E402


def test_the_panel_calibrates_a_take_on_the_sessions_calibration_take(addon, tmp_path):
    rec = six_tracker_recording(body_with_legs(1.78), random_mounts(2), duration=6.0, seed=2)
    cal, take = str(tmp_path / "calibration.csv"), str(tmp_path / "take.csv")
    write_csv(cal, rec, axes="openxr", units="m")
    write_csv(take, without_tpose(rec), axes="openxr", units="m")
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.filepath, s.calibration, s.calibration_take = 'FILE', take, 'AUTO', cal
    assert bpy.ops.manikin.find_tpose() == {'FINISHED'}
    assert s.calibration == 'TPOSE' and s.tpose_time < 1.2          # in the calibration take
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert "of calibration.csv: stature 1.78 m" in s.last_report and "not measured" not in s.last_report
    s.calibration_take, s.calibration = "", 'AUTO'
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    assert "tracker offsets not measured" in s.last_report           # its own: no T-pose


def test_the_command_line_takes_a_calibration_take():
    from blender_manikin import cli
    p = cli.build_parser()
    st = cli.solve_settings(p.parse_args(["solve", "t.csv", "--out", "o", "--calibration-take", "cal.csv",
                                          "--height", "1.8"]))
    assert st.calibration_take == "cal.csv" and st.calibration == "AUTO" and st.height == 1.8
    st = cli.solve_settings(p.parse_args(["solve", "t.csv", "--out", "o", "--height", "1.8"]))
    assert st.calibration_take is None and st.calibration == "MEASURE"
