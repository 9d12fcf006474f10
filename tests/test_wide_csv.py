"""Wide CSV layouts (one row per time step, a column group per device), detected automatically:
device names, column patterns, quaternion order, time units, length units and axes.  Every
fixture is made here from one known motion (Blender axes) written in the family's conventions."""
import os

import numpy as np
import pytest

from blender_manikin.core import formats
from blender_manikin.core import rotations as rot
from blender_manikin.core.recording import RecordingError, from_blender

T = 120
RATE = 90.0


def motion():
    """Blender-axes poses: the head turns slowly (facing -Y, then yawing, nodding and tilting), the
    hands in front."""
    t = np.arange(T) / RATE
    yaw = 0.8 * np.sin(2 * np.pi * 0.3 * t)
    R = rot.axis_angle_rotation(np.array([0, 0, 1.0]), yaw) @ \
        rot.axis_angle_rotation(np.array([1.0, 0, 0]), 0.3 * np.sin(2 * np.pi * 0.5 * t)) @ \
        rot.axis_angle_rotation(np.array([0, 1.0, 0]), 0.2 * np.cos(2 * np.pi * 0.4 * t))  # nods and tilts too
    head = np.stack([0.1 * np.sin(t), 0.05 * t, np.full(T, 1.62)], -1)
    pos = {"head": head}
    for d, sx in (("left_hand", 1.0), ("right_hand", -1.0)):
        off = np.array([0.25 * sx, -0.35, -0.35])
        pos[d] = head + np.einsum("tij,j->ti", R, off)
    # six-tracker setups: a waist tracker and two foot trackers
    pos["pelvis"] = head - np.array([0.0, -0.05, 0.62])
    pos["left_foot"] = np.stack([0.1 * np.sin(t) + 0.12, 0.05 * t, np.full(T, 0.09)], -1)
    pos["right_foot"] = np.stack([0.1 * np.sin(t) - 0.12, 0.05 * t + 0.1 * np.sin(3 * t), np.full(T, 0.09)], -1)
    quat = {d: rot.matrix_to_quat(R) for d in pos}
    return t, pos, quat


def euler_xyz(q, order):
    """Angles about x, y, z (radians) of quaternions ``q`` (w, x, y, z) as rotations about the
    fixed axes applied in ``order`` (first letter first), as a logger would write them."""
    rev = order[::-1]
    a = rot.matrix_to_euler(rot.quat_to_matrix(q), rev)
    out = np.empty_like(a)
    for n, c in enumerate(rev):
        out[:, "XYZ".index(c)] = a[:, n]
    return out


def write_wide(path, axes, units, names, comp, time_col, quat_order="xyzw", index_col=False, time_scale=1.0,
               euler=None):
    """Write the motion as a wide CSV: ``names`` device -> prefix, ``comp(prefix, kind, axis)`` -> column.
    euler: ``(order, "deg"|"rad")`` writes Euler angles x, y, z instead of quaternions."""
    t, pos, quat = motion()
    scale = {"m": 1.0, "cm": 100.0, "mm": 1000.0}[units]
    cols, data = [], []
    if index_col:
        cols.append("")
        data.append(np.arange(T, dtype=float))
    cols.append(time_col)
    if time_col == "delta_time_ms":
        data.append(np.r_[0.0, np.diff(t)] * 1000.0)
    elif time_col == "frame":
        data.append(np.arange(T, dtype=float))
    else:
        data.append(t * time_scale)
    for dev, prefix in names.items():
        p, q = from_blender(pos[dev], quat[dev], axes)
        for k, a in enumerate("xyz"):
            cols.append(comp(prefix, "pos", a))
            data.append(p[:, k] * scale)
        if euler:
            ang = euler_xyz(q, euler[0])
            ang = np.degrees(ang) if euler[1] == "deg" else ang
            for k, a in enumerate("xyz"):
                cols.append(comp(prefix, "rot", a))
                data.append(ang[:, k])
            continue
        qd = dict(zip("wxyz", q.T))
        for a in quat_order:
            cols.append(comp(prefix, "rot", a))
            data.append(qd[a])
    arr = np.stack(data, -1)
    with open(path, "w") as f:
        f.write(",".join(cols) + "\n")
        for row in arr:
            f.write(",".join(f"{v:.7f}" for v in row) + "\n")
    return pos


FAMILIES = {
    "unity_logger_ms_cm": dict(axes="unity", units="cm", time_col="timestamp", time_scale=1000.0,
                               names={"head": "hmd", "left_hand": "left_controller", "right_hand": "right_controller"},
                               comp=lambda p, k, a: f"{p}_{'pos' if k == 'pos' else 'rot'}_{a}"),
    "openxr_dotted_m": dict(axes="openxr", units="m", time_col="time", quat_order="wxyz",
                            names={"head": "head", "left_hand": "LeftHand", "right_hand": "RightHand"},
                            comp=lambda p, k, a: f"{p}.{'position' if k == 'pos' else 'rotation'}.{a}"),
    "pandas_index_delta_mm": dict(axes="openxr", units="mm", time_col="delta_time_ms", index_col=True,
                                  names={"head": "headset", "left_hand": "controller_left",
                                         "right_hand": "controller_right"},
                                  comp=lambda p, k, a: f"{p}_{a}" if k == "pos" else f"{p}_quat_{a}"),
    "unity_l_hand_m": dict(axes="unity", units="m", time_col="time",
                           names={"head": "HMD", "left_hand": "l_hand", "right_hand": "r_hand"},
                           comp=lambda p, k, a: f"{p}_{'position' if k == 'pos' else 'quat'}_{a}"),
    "unity_euler_degrees": dict(axes="unity", units="m", time_col="time", euler=("ZXY", "deg"),
                                names={"head": "hmd", "left_hand": "left_hand", "right_hand": "right_hand"},
                                comp=lambda p, k, a: f"{p}_{'position' if k == 'pos' else 'euler'}_{a}"),
    "openxr_euler_radians_frames": dict(axes="openxr", units="cm", time_col="frame", euler=("XYZ", "rad"),
                                        names={"head": "head", "left_hand": "controller_left",
                                               "right_hand": "controller_right"},
                                        comp=lambda p, k, a: f"{p}_{'pos' if k == 'pos' else 'rot'}_{a}"),
    "six_trackers_steamvr": dict(axes="openxr", units="m", time_col="time",
                                 names={"head": "hmd", "left_hand": "left_controller",
                                        "right_hand": "right_controller", "pelvis": "waist",
                                        "left_foot": "tracker_left_foot", "right_foot": "foot_r"},
                                 comp=lambda p, k, a: f"{p}_{'pos' if k == 'pos' else 'rot'}_{a}"),
    "six_trackers_unity": dict(axes="unity", units="cm", time_col="time",
                               names={"head": "HMD", "left_hand": "LeftHand", "right_hand": "RightHand",
                                      "pelvis": "Hip", "left_foot": "FootL", "right_foot": "RightFootTracker"},
                               comp=lambda p, k, a: f"{p}_{'position' if k == 'pos' else 'rotation'}_{a}"),
    "zup_blender": dict(axes="blender", units="m", time_col="t",
                        names={"head": "head", "left_hand": "hand_l", "right_hand": "hand_r"},
                        comp=lambda p, k, a: f"{p}_{'pos' if k == 'pos' else 'rot'}_{a}"),
}


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_each_family_is_detected_and_reads_back(tmp_path, family):
    spec = FAMILIES[family]
    path = tmp_path / f"{family}.csv"
    truth = write_wide(path, **spec)
    rec = formats.load_recording(path, rate=RATE if spec["time_col"] == "frame" else None)
    line = rec.metadata["detected"]
    assert line.startswith("wide layout: head=") and f"units {spec['units']}" in line, line
    assert rec.metadata["axes"] == spec["axes"], line
    assert "head at 1.6" in line
    _, _, quat = motion()
    assert sorted(rec.streams) == sorted(spec["names"]), line
    for dev in spec["names"]:
        s = rec.streams[dev]
        assert len(s.time) == T and abs(s.time[1] - 1 / RATE) < 1e-4, line
        assert np.abs(s.pos - truth[dev]).max() < 2e-4, (family, dev)
        err = np.degrees(rot.geodesic_angle(rot.quat_to_matrix(s.quat), rot.quat_to_matrix(quat[dev])))
        assert err.max() < 0.01, (family, dev, err.max())
    if spec.get("euler"):
        order, unit = spec["euler"]
        assert f"Euler angles in {'degrees' if unit == 'deg' else 'radians'}, fixed axes {order}" in line, line
        assert rec.metadata["layout"]["euler"] == {"order": order, "unit": unit}


def test_euler_order_and_frame_rate_are_stated_or_asked_for(tmp_path):
    from blender_manikin.core.io_wide_csv import save_layout
    path = tmp_path / "take.csv"
    write_wide(path, **FAMILIES["openxr_euler_radians_frames"])
    with pytest.raises(RecordingError, match=r"take.csv: the only time is the frame counter 'frame': give the "
                                             r"tracker rate \(--rate HZ"):
        formats.load_recording(path)
    rec = formats.load_recording(path, rate=RATE)
    assert "time=frame (frames) at 90 Hz" in rec.metadata["detected"]
    used = rec.metadata["layout"]
    assert used["time"] == {"column": "frame", "unit": "frames", "rate": RATE}
    # the layout file carries the rate and the order; a wrong order there gives other rotations
    lf = save_layout(tmp_path / "l.json", used)
    again = formats.load_recording(path, layout=str(lf))
    np.testing.assert_allclose(again.streams["head"].quat, rec.streams["head"].quat, atol=1e-12)
    assert "(stated order)" in again.metadata["detected"]
    lf2 = save_layout(tmp_path / "zyx.json", dict(used, euler={"order": "ZYX", "unit": "rad"}))
    other = formats.load_recording(path, layout=str(lf2))
    assert np.abs(other.streams["left_hand"].quat - rec.streams["left_hand"].quat).max() > 1e-3
    # a Unity logger's default is Unity's own order (Z, X, Y)
    p2 = tmp_path / "unity.csv"
    write_wide(p2, **FAMILIES["unity_euler_degrees"])
    assert "fixed axes ZXY (Unity's order)" in formats.load_recording(p2).metadata["detected"]


def test_a_frame_counted_wide_csv_solves_from_the_command_line(tmp_path, capsys):
    from blender_manikin import cli
    path = tmp_path / "take.csv"
    write_wide(path, **FAMILIES["openxr_euler_radians_frames"])
    assert cli.main(["solve", str(path), "--out", str(tmp_path / "o"), "--format", "json", "--height", "1.75",
                     "--rate", "90"]) == 0
    assert "time=frame (frames) at 90 Hz" in capsys.readouterr().out


def test_the_detection_line_reads_like_a_sentence(tmp_path):
    path = tmp_path / "take.csv"
    write_wide(path, **FAMILIES["unity_logger_ms_cm"])
    line = formats.load_recording(path).metadata["detected"]
    assert line == ("wide layout: head=hmd_*, hands=left_controller_*/right_controller_*; quaternions x,y,z,w; "
                    "time=timestamp in ms; units cm (head at 1.62 m); axes unity (left-handed), from the "
                    "hands' reach ahead of the head, the weakest cue: if the body faces backwards, set the "
                    "axes to openxr (Axes, --axes)")


def test_given_axes_and_units_override_the_detection(tmp_path):
    path = tmp_path / "take.csv"
    write_wide(path, **FAMILIES["openxr_dotted_m"])
    rec = formats.load_recording(path, axes="unity", units="m")
    assert rec.metadata["axes"] == "unity" and "axes unity (given)" in rec.metadata["detected"]


def test_ambiguous_or_incomplete_layouts_are_errors_naming_the_problem(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("time,hmd_pos_x,hmd_pos_y,hmd_pos_z,head_pos_x,head_pos_y,head_pos_z\n0,0,1.6,0,0,1.6,0\n")
    with pytest.raises(RecordingError, match="a.csv, line 1: two columns for head pos x"):
        formats.load_recording(p)
    p.write_text("time,hmd_pos_x,hmd_pos_y,hmd_pos_z,hmd_rot_x,hmd_rot_y\n0,0,1.6,0,0,0\n")
    with pytest.raises(RecordingError, match="a quaternion needs w, x, y, z, Euler angles x, y, z"):
        formats.load_recording(p)
    p.write_text("time,hmd_pos_x,hmd_pos_y,hmd_pos_z\n0,0,1.6,0\n1,0,1.6,0\n")
    with pytest.raises(RecordingError, match="no columns for left_hand, right_hand"):
        formats.load_recording(p)
    p.write_text("hmd_pos_x,hmd_pos_y,hmd_pos_z\n0,1.6,0\n")
    with pytest.raises(RecordingError, match="no time column"):
        formats.load_recording(p)


def test_a_wide_csv_solves(tmp_path):
    from blender_manikin.core.solve import SolveSettings, solve_recording
    path = tmp_path / "take.csv"
    write_wide(path, **FAMILIES["unity_logger_ms_cm"])
    out = solve_recording(path, SolveSettings(fps=30.0, height=1.78))
    assert out.result.num_frames > 30 and np.isfinite(out.result.positions).all()
    assert out.summary().startswith("wide layout: head=hmd_*")


def test_layout_files_fix_what_detection_would_guess(tmp_path):
    from blender_manikin.core.io_wide_csv import load_layout, save_layout
    path = tmp_path / "take.csv"
    truth = write_wide(path, **FAMILIES["unity_logger_ms_cm"])
    detected = formats.load_recording(path).metadata["layout"]
    assert detected["devices"]["head"]["pos"] == ["hmd_pos_x", "hmd_pos_y", "hmd_pos_z"]
    assert detected["devices"]["head"]["rot"] == ["hmd_rot_w", "hmd_rot_x", "hmd_rot_y", "hmd_rot_z"]
    assert detected["time"] == {"column": "timestamp", "unit": "ms"} and detected["axes"] == "unity"
    lf = save_layout(tmp_path / "layout.json", detected)
    again = formats.load_recording(path, layout=str(lf))
    assert again.metadata["detected"].startswith("layout file: head=hmd_*")
    assert np.abs(again.streams["head"].pos - truth["head"]).max() < 2e-4
    # the layout wins over a wrong guess: say the file is OpenXR in metres
    wrong = dict(detected, axes="openxr", units="m")
    lf2 = save_layout(tmp_path / "wrong.json", wrong)
    odd = formats.load_recording(path, layout=str(lf2))
    assert odd.metadata["axes"] == "openxr" and odd.metadata["units"] == "m"
    # bad layout files are named with their problem
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "wide_csv", "devices": {"elbow": {"pos": ["a", "b", "c"]}}, "time": {}}')
    with pytest.raises(RecordingError, match=r"bad.json.*unknown device 'elbow'.*\"time\" must be"):
        load_layout(bad)
    missing = dict(detected, devices={"head": {"pos": ["nope_x", "nope_y", "nope_z"], "rot": None}})
    lf3 = save_layout(tmp_path / "missing.json", missing)
    with pytest.raises(RecordingError, match="take.csv, line 1: the layout names column 'nope_x'"):
        formats.load_recording(path, layout=str(lf3))
    with pytest.raises(RecordingError, match="applies to wide-layout CSV"):
        formats.load_recording(_bsor(tmp_path), layout=str(lf))


def _bsor(tmp_path):
    from fixtures_recordings import synthetic_bsor
    p = tmp_path / "r.bsor"
    p.write_bytes(synthetic_bsor()[0])
    return p


def test_cli_save_layout_then_layout(tmp_path, capsys):
    from blender_manikin import cli
    path = tmp_path / "take.csv"
    write_wide(path, **FAMILIES["openxr_dotted_m"])
    lf = tmp_path / "layout.json"
    assert cli.main(["solve", str(path), "--out", str(tmp_path / "o"), "--format", "json", "--height", "1.75",
                     "--save-layout", str(lf)]) == 0
    assert load_json(lf)["devices"]["left_hand"]["pos"][0] == "LeftHand.position.x"
    assert cli.main(["solve", str(path), "--out", str(tmp_path / "o2"), "--format", "json", "--height", "1.75",
                     "--layout", str(lf)]) == 0
    out = capsys.readouterr().out
    assert "layout file: head=head_*" in out and "axes openxr (layout file)" in out


def load_json(p):
    import json
    return json.loads(open(p).read())


def test_bad_cells_name_their_line(tmp_path):
    p = tmp_path / "b.csv"
    write_wide(p, **FAMILIES["unity_logger_ms_cm"])
    lines = p.read_text().splitlines()
    cells = lines[5].split(",")
    cells[3] = "oops"
    lines[5] = ",".join(cells)
    lines[8] = lines[8] + ",1"
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match="b.csv, line 9: .*fields, the header has"):
        formats.load_recording(p)
    lines[8] = lines[8][:-2]
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match="b.csv, line 6: 'oops' is not a number"):
        formats.load_recording(p)
    cells[3] = ""                                            # an empty cell is a lost sample
    lines[5] = ",".join(cells)
    p.write_text("\n".join(lines) + "\n")
    rec = formats.load_recording(p)
    assert not rec.streams["head"].valid[4] and rec.streams["head"].valid[5]


def test_an_infinite_cell_is_a_lost_sample_without_warnings(tmp_path):
    """'inf' where a hand's position should be (a logger's overflow): the axes are still told from
    the other rows, quietly (no RuntimeWarning on the console), and the sample counts as lost."""
    import warnings
    p = tmp_path / "inf.csv"
    write_wide(p, **FAMILIES["unity_logger_ms_cm"])
    lines = p.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[5].split(",")
    cells[header.index("left_controller_pos_x")] = "inf"
    lines[5] = ",".join(cells)
    p.write_text("\n".join(lines) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = formats.load_recording(p)
    assert "axes unity" in rec.metadata["detected"]
    s = rec.streams["left_hand"]
    assert not np.all(np.isfinite(s.pos[4])) or not s.valid[4]


@pytest.mark.parametrize("axes", ["openxr", "unity"])
def test_a_take_mostly_at_the_sides_is_not_read_mirrored(tmp_path, axes):
    """The bundled example (a T-pose, walking with the hands at the sides, one reach, a wave),
    written as a wide CSV: its headset stands ahead of the hands most of the time, yet the reach
    decides the axes.  Voting on the hands' direction read it mirrored (left-handed for OpenXR),
    8 cm of headset offset then turned the wrong way."""
    from blender_manikin.core.resample import resample
    example = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples",
                           "example_recording.csv")
    rec = formats.load_recording(example)
    times, pos, quat, _, _ = resample(rec, 72.0, floor=None, check_units=False)
    from fixtures_recordings import write_wide_poses
    names = {"head": "hmd", "left_hand": "left_controller", "right_hand": "right_controller"}
    path = write_wide_poses(tmp_path / "example_wide.csv", times - times[0], pos, quat, names, axes)
    back = formats.load_recording(path)
    assert f"axes {axes} (" in back.metadata["detected"]
    np.testing.assert_allclose(back.streams["head"].pos, pos["head"], atol=1e-5)


@pytest.mark.parametrize("head,left,right,style", [
    ("CenterEyeAnchor", "LeftHandAnchor", "RightHandAnchor", "dot"),           # Meta OVRCameraRig
    ("CenterEyeAnchor", "LeftControllerAnchor", "RightControllerAnchor", "dot"),
    ("hmd", "MotionController_L", "MotionController_R", "underscore"),          # Unreal
    ("Main Camera", "LeftHand Controller", "RightHand Controller", "dot"),      # Unity XR rig
    ("XRHead", "LHand", "RHand", "dot"),
    ("head_pose", "left_hand_pose", "right_hand_pose", "underscore"),
    ("hmd", "controller_l", "controller_r", "underscore"),
])
def test_engine_rig_names_are_devices(head, left, right, style):
    from blender_manikin.core.io_wide_csv import parse_columns

    def cols(prefix):
        if style == "dot":
            return [f"{prefix}.position.{a}" for a in "xyz"] + [f"{prefix}.rotation.{a}" for a in "xyzw"]
        return [f"{prefix}_pos_{a}" for a in "xyz"] + [f"{prefix}_rot_{a}" for a in "xyzw"]

    groups, time_col, skipped = parse_columns(["time"] + cols(head) + cols(left) + cols(right))
    assert skipped == [] and time_col == (0, "time")
    # the prefixes as the file writes them (the detection line, the auto offsets' head name)
    assert {d: g["prefix"] for d, g in groups.items()} == {"head": head, "left_hand": left, "right_hand": right}


def _relocale(src, dst, delim, decimal_comma=False, time=None):
    """``src`` (a comma-separated wide CSV) rewritten with ``delim`` between fields, decimal commas,
    and ``time(seconds) -> text`` in the first column."""
    lines = open(src).read().splitlines()
    out = [lines[0].replace(",", delim)]
    for ln in lines[1:]:
        cells = ln.split(",")
        if time is not None:
            cells[0] = time(float(cells[0]))
        if decimal_comma:
            cells = [c.replace(".", ",") if k or time is None else c for k, c in enumerate(cells)]
        out.append(delim.join(cells))
    open(dst, "w").write("\n".join(out) + "\n")
    return dst


@pytest.mark.parametrize("delim,decimal_comma,said", [
    (";", True, "fields separated by semicolons, decimal commas; "),      # Unity on a German locale
    (";", False, "fields separated by semicolons; "),
    ("\t", False, "fields separated by tabs; "),
])
def test_semicolons_tabs_and_decimal_commas(tmp_path, delim, decimal_comma, said):
    src = tmp_path / "comma.csv"
    write_wide(src, **FAMILIES["openxr_dotted_m"])
    plain = formats.load_recording(src)
    rec = formats.load_recording(_relocale(src, tmp_path / "locale.csv", delim, decimal_comma))
    assert said in rec.metadata["detected"]
    for d in plain.streams:
        np.testing.assert_array_equal(rec.streams[d].pos, plain.streams[d].pos)
        np.testing.assert_array_equal(rec.streams[d].time, plain.streams[d].time)
    # the layout file keeps the separator and the decimal mark
    from blender_manikin.core.io_wide_csv import save_layout
    layout = rec.metadata["layout"]
    assert layout["delimiter"] == delim and layout["decimal"] == ("," if decimal_comma else ".")
    save_layout(tmp_path / "layout.json", layout)
    again = formats.load_recording(tmp_path / "locale.csv", layout=str(tmp_path / "layout.json"))
    np.testing.assert_array_equal(again.streams["head"].pos, plain.streams["head"].pos)


@pytest.mark.parametrize("fmt", [
    lambda s: f"2026-12-07T10:59:{58 + s:09.6f}",               # ISO 8601, local time
    lambda s: f"2026-12-07 09:59:{58 + s:09.6f}Z",              # a space for the T, UTC
    lambda s: f"2026-12-07T10:59:{58 + s:09.6f}+01:00",         # a zone offset
    lambda s: f"23:59:{59 + s:09.6f}" if s < 1 else f"00:00:{s - 1:09.6f}",   # past midnight
])
def test_iso_8601_times(tmp_path, fmt):
    """Loggers that write DateTime strings: seconds from the first, across a minute and (times of
    day) past midnight."""
    src = tmp_path / "comma.csv"
    write_wide(src, **FAMILIES["openxr_dotted_m"])
    plain = formats.load_recording(src)
    rec = formats.load_recording(_relocale(src, tmp_path / "iso.csv", ",", time=fmt))
    assert "time=time as ISO 8601" in rec.metadata["detected"]
    np.testing.assert_allclose(rec.streams["head"].time, plain.streams["head"].time, atol=2e-6)
    assert rec.metadata["layout"]["time"]["unit"] == "iso8601"


def test_a_time_that_is_not_iso_8601_names_its_line(tmp_path):
    src = tmp_path / "comma.csv"
    write_wide(src, **FAMILIES["openxr_dotted_m"])
    bad = _relocale(src, tmp_path / "iso.csv", ";", decimal_comma=True,
                    time=lambda s: "7.12.2026 10:00" if s > 0.5 else f"2026-12-07T10:00:{s:09.6f}")
    with pytest.raises(RecordingError, match=r"iso.csv, line 48: '7.12.2026 10:00' is not an ISO 8601 date "
                                             r"and time, as the first time is"):
        formats.load_recording(bad)


def test_whole_milliseconds_are_not_times_of_day(tmp_path):
    """Python reads "11" and "22" as ISO 8601 hours: integer times stay numbers."""
    src = tmp_path / "comma.csv"
    write_wide(src, **FAMILIES["openxr_dotted_m"])
    plain = formats.load_recording(src)
    path = _relocale(src, tmp_path / "ms.csv", ",", time=lambda s: f"{round(s * 1000) + 11}")
    text = open(path).read()
    open(path, "w").write("timestamp" + text[len("time"):])
    rec = formats.load_recording(path)
    assert "time=timestamp in ms" in rec.metadata["detected"]
    np.testing.assert_allclose(rec.streams["head"].time, plain.streams["head"].time, atol=1e-3)


@pytest.mark.parametrize("name,scale,unit", [("timestamp", 1.0, "s"), ("timestamp", 1e3, "ms"),
                                             ("time", 1e3, "ms"), ("time_ms", 1e3, "ms")])
def test_a_timestamp_in_unix_seconds_is_read_in_seconds(tmp_path, name, scale, unit):
    """A ``timestamp`` column is as often Unix time in seconds (Python's ``time.time()``) as
    milliseconds: its steps decide, as a ``time`` column's do, so a 90 Hz take keeps its length."""
    src = tmp_path / "plain.csv"
    write_wide(src, **FAMILIES["openxr_dotted_m"])
    plain = formats.load_recording(src)
    path = _relocale(src, tmp_path / "stamped.csv", ",", time=lambda s: f"{(1.7e9 + s) * scale:.6f}")
    text = open(path).read()
    open(path, "w").write(name + text[len("time"):])
    rec = formats.load_recording(path)
    assert f"time={name} in {unit}" in rec.metadata["detected"]
    np.testing.assert_allclose(rec.streams["head"].time - rec.streams["head"].time[0],
                               plain.streams["head"].time - plain.streams["head"].time[0], atol=1e-4)


def test_unity_vector_and_quaternion_tuples(tmp_path):
    """A logger that writes Unity's Vector3 / Quaternion ToString() into one field each:
    "(0.10000, 1.60000, 0.20000)" and "(x, y, z, w)"; the layout file names the spread columns."""
    from blender_manikin.core.io_wide_csv import save_layout
    t, pos, quat = motion()
    names = {"head": "Head", "left_hand": "LeftHand", "right_hand": "RightHand"}
    rows = ["time," + ",".join(f"{n}Position,{n}Rotation" for n in names.values())]
    for k in range(T):
        cells = [f"{t[k]:.5f}"]
        for d in names:
            p, q = from_blender(pos[d][k], quat[d][k], "unity")
            for v in (p, q[[1, 2, 3, 0]]):
                cells.append("(" + ", ".join(f"{x:.5f}" for x in v) + ")")
        rows.append(",".join(cells))
    path = tmp_path / "tostring.csv"
    path.write_text("\n".join(rows) + "\n")
    rec = formats.load_recording(path, axes="unity")
    assert "quaternions x,y,z,w; vectors and quaternions as (x, y, z[, w]) tuples; time=time in s" \
        in rec.metadata["detected"]
    assert rec.metadata["layout"]["devices"]["head"]["pos"] == ["HeadPosition_x", "HeadPosition_y", "HeadPosition_z"]
    for d in names:
        assert np.abs(rec.streams[d].pos - pos[d]).max() < 1e-5
        err = np.degrees(rot.geodesic_angle(rot.quat_to_matrix(rec.streams[d].quat), rot.quat_to_matrix(quat[d])))
        assert err.max() < 0.01
    save_layout(tmp_path / "layout.json", rec.metadata["layout"])
    again = formats.load_recording(path, layout=str(tmp_path / "layout.json"))
    np.testing.assert_array_equal(again.streams["head"].pos, rec.streams["head"].pos)


#: Unreal Engine's axes from Blender's: +X forward (Blender -Y), +Y right (Blender -X), +Z up;
#: left-handed.  Written out here, not taken from the reader, so the test checks the reader.
M_UNREAL = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def unreal_rotator(R):
    """Pitch, yaw, roll (degrees) of rotation matrices ``R`` ``(T, 3, 3)`` in Unreal's axes (the
    columns the images of X, Y, Z), inverting UE's ``FRotationMatrix``: forward
    ``(CP CY, CP SY, SP)``, right ``(SR SP CY - CR SY, SR SP SY + CR CY, -SR CP)``, up
    ``(-(CR SP CY + SR SY), CY SR - CR SP SY, CR CP)``."""
    f, r, u = R[:, :, 0], R[:, :, 1], R[:, :, 2]
    return (np.degrees(np.arcsin(np.clip(f[:, 2], -1, 1))), np.degrees(np.arctan2(f[:, 1], f[:, 0])),
            np.degrees(np.arctan2(-r[:, 2], u[:, 2])))


def write_unreal(path, rotation):
    """The motion as an Unreal Engine logger writes it: centimetres, Unreal's axes, devices
    ``Camera`` / ``MotionController_L`` / ``MotionController_R``; rotation ``"quat"`` (X, Y, Z, W),
    ``"rotator"`` (Pitch, Yaw, Roll columns) or ``"euler"`` (``FRotator::Euler()``: X, Y, Z =
    roll, pitch, yaw)."""
    t, pos, quat = motion()
    cols, data = ["Time"], [t]
    for dev, name in (("head", "Camera"), ("left_hand", "MotionController_L"), ("right_hand", "MotionController_R")):
        R = M_UNREAL @ rot.quat_to_matrix(quat[dev]) @ M_UNREAL.T
        p = pos[dev] @ M_UNREAL.T * 100.0
        cols += [f"{name}_Location_{a}" for a in "XYZ"]
        data += list(p.T)
        pitch, yaw, roll = unreal_rotator(R)
        if rotation == "quat":
            cols += [f"{name}_Rotation_{a}" for a in "XYZW"]
            data += list(rot.matrix_to_quat(R)[:, [1, 2, 3, 0]].T)
        elif rotation == "rotator":
            cols += [f"{name}_Rotation_{a}" for a in ("Pitch", "Yaw", "Roll")]
            data += [pitch, yaw, roll]
        else:
            cols += [f"{name}_Rotation_{a}" for a in "XYZ"]
            data += [roll, pitch, yaw]
    with open(path, "w") as f:
        f.write(",".join(cols) + "\n")
        for row in np.stack(data, -1):
            f.write(",".join(f"{v:.7f}" for v in row) + "\n")


@pytest.mark.parametrize("rotation", ["quat", "rotator", "euler"])
def test_unreal_logs_are_read_in_unreal_axes(tmp_path, rotation):
    """Unreal's Z-up, left-handed, X-forward axes were read as Blender's: the take mirrored and
    turned 90° (the left hand on the performer's right, the solved wrists 77 cm off), and its
    Pitch / Yaw / Roll columns were left out as no rotation at all."""
    path = tmp_path / "unreal.csv"
    write_unreal(path, rotation)
    rec = formats.load_recording(path)
    line = rec.metadata["detected"]
    assert rec.metadata["axes"] == "unreal" and "axes unreal (left-handed)" in line, line
    assert "units cm" in line, line
    _, pos, quat = motion()
    for dev in ("head", "left_hand", "right_hand"):
        s = rec.streams[dev]
        assert np.abs(s.pos - pos[dev]).max() < 2e-4, (rotation, dev)
        err = np.degrees(rot.geodesic_angle(rot.quat_to_matrix(s.quat), rot.quat_to_matrix(quat[dev])))
        assert err.max() < 0.01, (rotation, dev, err.max())
    if rotation != "quat":
        assert "Unreal rotators (roll, pitch, yaw) in degrees" in line, line
        # the layout file keeps the rotator convention: read again through it, the same poses
        from blender_manikin.core.io_wide_csv import save_layout
        again = formats.load_recording(path, layout=str(save_layout(tmp_path / "l.json", rec.metadata["layout"])))
        np.testing.assert_allclose(again.streams["left_hand"].quat, rec.streams["left_hand"].quat, atol=1e-12)
    # a Blender-axes file of the same take is still read as Blender's
    p2 = tmp_path / "blender.csv"
    write_wide(p2, **FAMILIES["zup_blender"])
    assert formats.load_recording(p2).metadata["axes"] == "blender"
    # and the axes can be given (the panel's Axes, --axes unreal)
    assert formats.load_recording(path, axes="unreal").metadata["axes"] == "unreal"


@pytest.mark.parametrize("style", ["{d}_m{r}{c}", "{d}.m[{r}][{c}]"])
def test_openvr_pose_matrices(tmp_path, style):
    """OpenVR's ``HmdMatrix34_t`` poses (3x4, row-major, the position in the last column, right-handed
    Y up) logged one element a column, trackers included: such a file was read as a native CSV
    and refused for lacking ``device, px, ...``."""
    t, pos, quat = motion()
    names = {"head": "hmd", "left_hand": "controller_left", "right_hand": "controller_right",
             "pelvis": "tracker_waist", "left_foot": "tracker_left_foot", "right_foot": "tracker_right_foot"}
    cols, data = ["time"], [t]
    for dev, name in names.items():
        p, q = from_blender(pos[dev], quat[dev], "openxr")
        R = rot.quat_to_matrix(q)
        for r in range(3):
            for c in range(4):
                cols.append(style.format(d=name, r=r, c=c))
                data.append(R[:, r, c] if c < 3 else p[:, r])
    arr = np.stack(data, -1)
    arr[5, 1:] = np.nan                                  # a lost sample
    path = tmp_path / "openvr.csv"
    with open(path, "w") as f:
        f.write(",".join(cols) + "\n")
        for row in arr:
            f.write(",".join("" if np.isnan(v) else f"{v:.7f}" for v in row) + "\n")
    rec = formats.load_recording(path)
    line = rec.metadata["detected"]
    assert "3x4 pose matrices (row-major)" in line and rec.metadata["axes"] == "openxr", line
    for dev in names:
        s = rec.streams[dev]
        ok = np.arange(T) != 5
        assert not s.valid[5] and s.valid[ok].all(), dev
        assert np.abs(s.pos[ok] - pos[dev][ok]).max() < 2e-4, dev
        err = np.degrees(rot.geodesic_angle(rot.quat_to_matrix(s.quat[ok]), rot.quat_to_matrix(quat[dev][ok])))
        assert err.max() < 0.01, (dev, err.max())
    from blender_manikin.core.io_wide_csv import save_layout
    again = formats.load_recording(path, layout=str(save_layout(tmp_path / "l.json", rec.metadata["layout"])))
    np.testing.assert_allclose(again.streams["pelvis"].quat[ok], rec.streams["pelvis"].quat[ok], atol=1e-12)
    # a matrix without its position column is named
    bad = tmp_path / "bad.csv"
    with open(bad, "w") as f:
        f.write(",".join(c for c in cols if not c.startswith("hmd") or not c.endswith(("23", "[2][3]"))) + "\n")
    with pytest.raises(RecordingError, match=r"bad.csv, line 1: head: pose matrix without m23"):
        formats.load_recording(bad)


@pytest.mark.parametrize("rotation", ["rotator", "quat"])
def test_unreal_tostring_cells(tmp_path, rotation):
    """A Blueprint logger appends each pose's ToString(): ``X=36.935 Y=-44.006 Z=162.432`` (FVector),
    ``P=-0.017 Y=-29.943 R=0.027`` (FRotator) or ``X=.. Y=.. Z=.. W=..`` (FQuat) in one field, under
    ``HMDLocation``, ``LeftControllerRotation``: such a file was refused as a native CSV without
    ``device, px, ...`` (and ``HMDLocation`` split into columns was no device)."""
    t, pos, quat = motion()
    names = (("head", "HMD"), ("left_hand", "LeftController"), ("right_hand", "RightController"))
    cells = [[f"{v:.4f}" for v in t]]
    for dev, _ in names:
        R = M_UNREAL @ rot.quat_to_matrix(quat[dev]) @ M_UNREAL.T
        p = pos[dev] @ M_UNREAL.T * 100.0
        cells.append([f"X={a:.3f} Y={b:.3f} Z={c:.3f}" for a, b, c in p])
        if rotation == "rotator":
            cells.append([f"P={a:.6f} Y={b:.6f} R={c:.6f}" for a, b, c in zip(*unreal_rotator(R))])
        else:
            cells.append([f"X={x:.9f} Y={y:.9f} Z={z:.9f} W={w:.9f}" for w, x, y, z in rot.matrix_to_quat(R)])
    path = tmp_path / "unreal_log.csv"
    with open(path, "w") as f:
        f.write("Time," + ",".join(f"{n}Location,{n}Rotation" for _, n in names) + "\n")
        for row in zip(*cells):
            f.write(",".join(row) + "\n")
    rec = formats.load_recording(path)
    line = rec.metadata["detected"]
    assert rec.metadata["axes"] == "unreal" and "Unreal's X=.. Y=.. Z=.." in line, line
    for dev, _ in names:
        s = rec.streams[dev]
        assert np.abs(s.pos - pos[dev]).max() < 2e-5, dev              # ToString's 3 decimals of a centimetre
        err = np.degrees(rot.geodesic_angle(rot.quat_to_matrix(s.quat), rot.quat_to_matrix(quat[dev])))
        assert err.max() < 0.01, (dev, err.max())


def _write_columns(path, cols, data, fmt="{:.7f}"):
    with open(path, "w") as f:
        f.write(",".join(cols) + "\n")
        for row in np.stack(data, -1):
            f.write(",".join(fmt.format(v) for v in row) + "\n")


def test_pitch_yaw_roll_columns_of_a_y_up_file_are_not_taken_for_unreal(tmp_path):
    """Pitch / yaw / roll columns made a file Unreal's (Z up) without looking at its positions:
    a Unity logger's eulerAngles named so (Y up) was read lying down, the head at -0.03 m (before
    those columns were read, it was read upright without rotations).  Now refused, naming the
    columns, the up axis the head stands along and the way out; so is a rotator read in axes
    given as another convention's."""
    t, pos, quat = motion()
    cols, data = ["time"], [t]
    for dev, name in (("head", "Head"), ("left_hand", "LeftHand"), ("right_hand", "RightHand")):
        p, q = from_blender(pos[dev], quat[dev], "unity")
        cols += [f"{name}_pos_{a}" for a in "xyz"] + [f"{name}_rot_{a}" for a in ("pitch", "yaw", "roll")]
        data += list(p.T) + list(np.degrees(rot.matrix_to_fixed_axes_euler(rot.quat_to_matrix(q), "ZXY")).T)
    path = tmp_path / "unity_pyr.csv"
    _write_columns(path, cols, data)
    with pytest.raises(RecordingError, match=r"unity_pyr.csv, line 1: .*Head_rot_pitch.*\(Y up, .*layout file"):
        formats.load_recording(path)
    unreal = tmp_path / "unreal.csv"
    write_unreal(unreal, "rotator")
    with pytest.raises(RecordingError, match=r"unreal.csv, line 1: .*Camera_Rotation_Pitch.*axes blender"):
        formats.load_recording(unreal, axes="blender")


def test_a_rotator_without_its_roll_is_named(tmp_path):
    """A rotator missing a column was refused as "rotation columns ['y', 'z']: a quaternion needs
    w, x, y, z, Euler angles x, y, z", naming neither its pitch/yaw columns nor the roll."""
    path = tmp_path / "unreal.csv"
    write_unreal(path, "rotator")
    lines = path.read_text().splitlines()
    k = lines[0].split(",").index("Camera_Rotation_Roll")
    half = tmp_path / "half.csv"
    half.write_text("\n".join(",".join(c for i, c in enumerate(ln.split(",")) if i != k) for ln in lines) + "\n")
    with pytest.raises(RecordingError, match=r"half.csv, line 1: head: rotator columns pitch, yaw without roll"):
        formats.load_recording(half)


def test_an_all_zero_pose_matrix_is_a_lost_sample(tmp_path):
    """OpenVR leaves a pose it has not got as zeros, and loggers write them: such a 3x4 matrix
    (no rotation at all) was read as a valid sample, the identity rotation at the origin."""
    t, pos, quat = motion()
    cols, data = ["time"], [t]
    for dev, name in (("head", "hmd"), ("left_hand", "controller_left"), ("right_hand", "controller_right")):
        p, q = from_blender(pos[dev], quat[dev], "openxr")
        R = rot.quat_to_matrix(q)
        for r in range(3):
            for c in range(4):
                cols.append(f"{name}_m{r}{c}")
                data.append(R[:, r, c] if c < 3 else p[:, r])
    data = [np.where(np.arange(T) == 5, 0.0, d) if k else d for k, d in enumerate(data)]
    path = tmp_path / "openvr_zeros.csv"
    _write_columns(path, cols, data)
    rec = formats.load_recording(path)
    for dev in ("head", "left_hand", "right_hand"):
        s = rec.streams[dev]
        assert not s.valid[5] and s.valid[np.arange(T) != 5].all(), dev


@pytest.mark.parametrize("style", ["unreal", "unity"])
def test_an_empty_tostring_cell_is_a_lost_sample(tmp_path, style):
    """An empty cell is a lost sample, but an empty ToString() field (a controller not tracked
    yet, or lost) was not spread: on the first row the file was refused as "left_hand: position
    columns [] (need x, y, z)", further on as "17 fields, the header has 19"."""
    t, pos, quat = motion()
    names = (("head", "HMD"), ("left_hand", "LeftController"), ("right_hand", "RightController"))
    cells = [[f"{v:.4f}" for v in t]]
    for dev, _ in names:
        if style == "unreal":
            R = M_UNREAL @ rot.quat_to_matrix(quat[dev]) @ M_UNREAL.T
            cells.append([f"X={a:.3f} Y={b:.3f} Z={c:.3f}" for a, b, c in pos[dev] @ M_UNREAL.T * 100.0])
            cells.append([f"P={a:.6f} Y={b:.6f} R={c:.6f}" for a, b, c in zip(*unreal_rotator(R))])
        else:
            p, q = from_blender(pos[dev], quat[dev], "unity")
            cells.append(["(" + ", ".join(f"{x:.5f}" for x in v) + ")" for v in p])
            cells.append(["(" + ", ".join(f"{x:.5f}" for x in v) + ")" for v in q[:, [1, 2, 3, 0]]])
    cells[3][0] = cells[4][0] = cells[3][7] = cells[4][7] = ""   # the left controller lost: first row, and later
    path = tmp_path / "tostring.csv"
    with open(path, "w") as f:
        f.write("Time," + ",".join(f"{n}Location,{n}Rotation" for _, n in names) + "\n")
        for row in zip(*cells):
            f.write(",".join(row) + "\n")
    rec = formats.load_recording(path, axes=None if style == "unreal" else "unity")
    s = rec.streams["left_hand"]
    assert not s.valid[0] and not s.valid[7] and s.valid[1:7].all() and s.valid[8:].all()
    assert np.abs(s.pos[8:] - pos["left_hand"][8:]).max() < 2e-5
    assert rec.streams["head"].valid.all()


@pytest.mark.parametrize("axes", ["blender", "unreal", "unity", "openxr"])
def test_a_head_without_rotation_columns_does_not_decide_the_axes_by_where_it_faces(tmp_path, axes):
    """A headset logged by position only, its controllers with rotations: the axes were chosen by
    the head's orientation, taken as the identity, so the way the performer happened to face
    decided (turned a quarter or half turn, a Blender file was read as Unreal's, a Unity file as
    OpenXR's); the positions decide now, as for a file with no rotations at all."""
    t, pos, quat = motion()
    for turn in (90, 180):
        Rz = rot.axis_angle_rotation(np.array([0, 0, 1.0]), np.full(T, np.radians(turn)))
        cols, data = ["time"], [t]
        for dev in ("head", "left_hand", "right_hand"):
            p, q = from_blender(np.einsum("tij,tj->ti", Rz, pos[dev]),
                                rot.matrix_to_quat(Rz @ rot.quat_to_matrix(quat[dev])), axes)
            cols += [f"{dev}_pos_{a}" for a in "xyz"]
            data += list(p.T)
            if dev != "head":
                cols += [f"{dev}_rot_{a}" for a in "wxyz"]
                data += list(q.T)
        path = tmp_path / f"turned_{turn}.csv"
        _write_columns(path, cols, data, "{:.6f}")
        assert formats.load_recording(path).metadata["axes"] == axes, turn


def test_a_pose_matrix_beside_euler_angles_is_named(tmp_path):
    """A headset's pose matrix beside controllers' Euler angles was refused as "some devices have
    quaternion and others Euler-angle columns: left_hand Euler, right_hand Euler", naming no device
    with a quaternion: the matrix is named now."""
    t, pos, quat = motion()
    cols, data = ["time"], [t]
    for dev, name in (("head", "hmd"), ("left_hand", "controller_left"), ("right_hand", "controller_right")):
        p, q = from_blender(pos[dev], quat[dev], "openxr")
        R = rot.quat_to_matrix(q)
        if dev == "head":
            for r in range(3):
                for c in range(4):
                    cols.append(f"{name}_m{r}{c}")
                    data.append(R[:, r, c] if c < 3 else p[:, r])
        else:
            cols += [f"{name}_pos_{a}" for a in "xyz"] + [f"{name}_euler_{a}" for a in "xyz"]
            data += list(p.T) + list(rot.matrix_to_fixed_axes_euler(R, "XYZ").T)
    path = tmp_path / "mixed.csv"
    _write_columns(path, cols, data)
    with pytest.raises(RecordingError, match=r"mixed.csv, line 1: .*head pose matrix, left_hand Euler"):
        formats.load_recording(path)
