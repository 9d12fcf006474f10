"""Unity or OpenXR for files that do not say (``core/axes_detect.py``): takes whose hands never
reach ahead of the headset (walking with the hands at the sides; standing and looking around)
are read the right way from the walking direction and the head's turns, where the hands'
reach alone read them mirrored.  Every take is made here by FK-like numpy geometry, Blender
axes, and written in each convention."""
import numpy as np
import pytest

from blender_manikin.core import axes_detect as ad
from blender_manikin.core import formats
from blender_manikin.core import rotations as rot
from blender_manikin.core.recording import from_blender

RATE = 72.0
Z = np.array([0.0, 0.0, 1.0])
#: the headset's pose from the neck's turning point, in the head's frame (Blender device axes:
#: -Y forward, +Z up): 9 cm ahead, 11 cm up
HEADSET_FROM_NECK = np.array([0.0, -0.09, 0.11])


def _take(seconds, body_xy, body_yaw, head_yaw, head_pitch, swing=0.12):
    """Device poses (Blender axes, metres) of a performer whose neck is at ``body_xy`` (1.50 m
    up), body turned ``body_yaw`` and head ``head_yaw`` / ``head_pitch`` (radians, ``(T,)``):
    the headset ahead of the neck, the hands hanging at the sides 12 cm behind the headset and
    swinging ``swing`` metres to and fro.  Returns ``(time, pos, quat)``, quaternions wxyz."""
    t = np.arange(int(seconds * RATE)) / RATE
    neck = np.concatenate([body_xy, np.full((len(t), 1), 1.50)], -1)
    R_body = rot.axis_angle_rotation(Z, body_yaw)
    R_head = R_body @ rot.axis_angle_rotation(Z, head_yaw) @ rot.axis_angle_rotation(np.array([1.0, 0, 0]), head_pitch)
    pos = {"head": neck + np.einsum("tij,j->ti", R_head, HEADSET_FROM_NECK)}
    swing = swing * np.sin(2 * np.pi * 0.9 * t)
    for d, x, s in (("left_hand", 0.2, 1.0), ("right_hand", -0.2, -1.0)):
        local = np.stack([np.full_like(t, x), 0.03 + s * swing, np.full_like(t, -0.62)], -1)
        pos[d] = neck + np.einsum("tij,tj->ti", R_body, local)
    quat = {"head": rot.matrix_to_quat(R_head), "left_hand": rot.matrix_to_quat(R_body),
            "right_hand": rot.matrix_to_quat(R_body)}
    return t, pos, quat


def walking_take(seconds=8.0):
    """Walking a wide curve at 1.2 m/s the way the body faces, the head glancing about."""
    t = np.arange(int(seconds * RATE)) / RATE
    yaw = 0.2 * t
    fwd = np.stack([np.sin(yaw), -np.cos(yaw)], -1)           # Rz(yaw) @ (0, -1, 0)
    xy = np.cumsum(1.2 * fwd / RATE, 0)
    return _take(seconds, xy, yaw, 0.25 * np.sin(2 * np.pi * 0.3 * t), 0.1 * np.sin(2 * np.pi * 0.2 * t))


def stepping_back_take(seconds=4.0):
    """Walking backwards at 0.9 m/s along a slow curve, facing ahead."""
    t = np.arange(int(seconds * RATE)) / RATE
    yaw = 0.15 * t
    fwd = np.stack([np.sin(yaw), -np.cos(yaw)], -1)
    xy = np.cumsum(-0.9 * fwd / RATE, 0)
    return _take(seconds, xy, yaw, 0.2 * np.sin(2 * np.pi * 0.3 * t), np.zeros_like(t), swing=0.05)


def looking_around_take(seconds=8.0):
    """Standing (1 cm of sway) and looking left and right, up and down."""
    t = np.arange(int(seconds * RATE)) / RATE
    xy = 0.01 * np.stack([np.sin(2 * np.pi * 0.1 * t), np.cos(2 * np.pi * 0.13 * t)], -1)
    return _take(seconds, xy, np.zeros_like(t), 0.8 * np.sin(2 * np.pi * 0.25 * t),
                 0.25 * np.sin(2 * np.pi * 0.4 * t), swing=0.02)


def in_axes(take, axes):
    t, pos, quat = take
    out_p, out_q = {}, {}
    for d in pos:
        out_p[d], out_q[d] = from_blender(pos[d], quat[d], axes)
    return t, out_p, out_q


@pytest.mark.parametrize("axes", ["unity", "openxr"])
@pytest.mark.parametrize("make,cue", [(walking_take, "walking direction"), (looking_around_take, "head's turns")])
def test_hands_at_the_sides_are_read_the_right_way(make, cue, axes):
    t, pos, quat = in_axes(make(), axes)
    other = "openxr" if axes == "unity" else "unity"
    ev = {a: ad.facing_evidence(t, pos, quat, a) for a in (axes, other)}
    # the hands stand 12 cm behind the headset: their reach alone says the other convention
    assert ev[other].reach > ev[axes].reach
    chosen, why = ad.choose_axes(t, pos, lambda a: quat, ("unity", "openxr"))
    assert chosen == axes and cue in why


def test_the_cues_measure_what_they_say():
    t, pos, quat = in_axes(walking_take(), "openxr")
    ev = ad.facing_evidence(t, pos, quat, "openxr")
    assert 7.0 < ev.walk <= 8.0                  # 8 s of walking, the head glancing up to 14 degrees
    t, pos, quat = in_axes(looking_around_take(), "openxr")
    ev = ad.facing_evidence(t, pos, quat, "openxr")
    assert ev.walk == 0.0
    assert 0.07 < ev.pivot < 0.10                # the neck 9 cm behind the headset
    mirrored = ad.facing_evidence(t, pos, quat, "unity")
    assert mirrored.pivot == pytest.approx(-ev.pivot) and mirrored.reach == pytest.approx(-ev.reach)


def test_a_head_that_never_turns_gives_no_pivot():
    t, pos, quat = in_axes(_take(4.0, np.zeros((int(4.0 * RATE), 2)), np.zeros(int(4.0 * RATE)),
                                 np.zeros(int(4.0 * RATE)), np.zeros(int(4.0 * RATE))), "unity")
    ev = ad.facing_evidence(t, pos, quat, "unity")
    assert ev.walk == 0.0 and abs(ev.pivot) < 1e-6
    axes, why = ad.choose_axes(t, pos, lambda a: quat, ("unity", "openxr"))
    assert why.startswith("from the hands' reach ahead of the head, the weakest cue")
    other = "openxr" if axes == "unity" else "unity"
    assert f"set the axes to {other} (Axes, --axes)" in why


def test_lost_samples_do_not_decide(tmp_path):
    t, pos, quat = in_axes(walking_take(), "unity")
    pos["head"][100:130] = np.nan
    quat["head"][300:310] = np.nan
    assert ad.choose_axes(t, pos, lambda a: quat, ("unity", "openxr"))[0] == "unity"


@pytest.mark.parametrize("axes", ["unity", "openxr"])
def test_a_wide_csv_of_walking_with_the_hands_at_the_sides(tmp_path, axes):
    from fixtures_recordings import write_wide_poses
    t, pos, quat = walking_take()
    names = {"head": "hmd", "left_hand": "left_controller", "right_hand": "right_controller"}
    path = write_wide_poses(tmp_path / "walk.csv", t, pos, quat, names, axes)
    rec = formats.load_recording(path)
    hand = "left-handed" if axes == "unity" else "right-handed"
    line = rec.metadata["detected"]
    assert f"axes {axes} ({hand})" in line and "from the walking direction (" in line
    np.testing.assert_allclose(rec.streams["head"].pos, pos["head"], atol=1e-5)


@pytest.mark.parametrize("units,scale", [("m", 1.0), ("cm", 100.0)])
@pytest.mark.parametrize("axes", ["unity", "openxr"])
@pytest.mark.parametrize("origin,up_how", [
    ((-12.0, -15.0, 0.0), None),                                       # the level's origin far away
    ((0.0, 0.0, -40.0), "Y up from the hands below the head"),          # the level's floor 40 m up
])
def test_a_world_space_log_far_from_the_origin(tmp_path, axes, units, scale, origin, up_how):
    """A game's log in world space: the player walked (thumbstick locomotion) 12-20 m from the
    level's origin, or stands on a floor 40 m above it.  The head's largest coordinate said
    centimetres for a file in metres, and the horizontal axis the player stood furthest along
    was taken for up."""
    from fixtures_recordings import write_wide_poses
    t, pos, quat = walking_take()
    pos = {d: (p - np.array(origin)) * scale for d, p in pos.items()}
    names = {"head": "Main Camera", "left_hand": "LeftHand Controller", "right_hand": "RightHand Controller"}
    path = write_wide_poses(tmp_path / "world.csv", t, pos, quat, names, axes)
    rec = formats.load_recording(path)
    line = rec.metadata["detected"]
    height = 1.61 - origin[2]
    assert f"units {units} (head at {height:.2f} m)" in line and f"axes {axes} (" in line, line
    if up_how:
        assert up_how in line, line
    else:
        assert "from the hands below" not in line, line
    np.testing.assert_allclose(rec.streams["head"].pos, pos["head"] / scale, atol=1e-5)


def test_the_head_height_decides_up_when_it_is_clear():
    t, pos, quat = walking_take(2.0)                   # 2.4 m of walk from the origin, head 1.61 m up
    for axes, up in (("openxr", 1), ("blender", 2)):
        p, q = in_axes((t, pos, quat), axes)[1:]
        assert ad.up_axis(p, q) == (up, "the head's height")
    assert ad.length_units({d: 1000 * p for d, p in pos.items()})[0] == "mm"


def _heading_error_deg(quat, body_yaw):
    """Degrees between the level forward of device quaternions (Blender axes) and the body's."""
    f = np.einsum("tij,j->ti", rot.quat_to_matrix(quat), np.array([0.0, -1.0, 0.0]))
    want = np.stack([np.sin(body_yaw), -np.cos(body_yaw)], -1)
    return np.degrees(np.arccos(np.clip(np.sum(f[:, :2] * want, -1) / np.linalg.norm(f[:, :2], axis=-1), -1, 1)))


@pytest.mark.parametrize("axes", ["unity", "openxr"])
@pytest.mark.parametrize("make,yaw", [(walking_take, lambda t: 0.2 * t), (looking_around_take, lambda t: 0 * t),
                                      (stepping_back_take, lambda t: 0.15 * t)])
def test_positions_without_orientations(tmp_path, axes, make, yaw):
    """A logger that writes positions only: the axes from the walking direction (or the reach)
    against the hands' left-right line, and level orientations facing that heading; the body was
    taken as facing one way all along."""
    t, pos, quat = make()
    cols, data = ["time"], [t]
    for d, n in (("head", "hmd"), ("left_hand", "left_controller"), ("right_hand", "right_controller")):
        p = from_blender(pos[d], None, axes)[0]
        cols += [f"{n}_pos_{a}" for a in "xyz"]
        data += list(p.T)
    path = tmp_path / "positions.csv"
    np.savetxt(path, np.stack(data, -1), delimiter=",", header=",".join(cols), comments="", fmt="%.6f")
    # standing with the hands at the sides, the axes cannot be told without orientations; a step
    # back is a walk backwards (it says the other convention), but it does not turn the body
    rec = formats.load_recording(path, axes=None if make is walking_take else axes)
    line = rec.metadata["detected"]
    assert "no orientation columns for head, left_hand, right_hand: level, facing the hands' left-right line" in line
    assert f"axes {axes} (" in line, line
    for d in ("head", "left_hand", "right_hand"):
        err = _heading_error_deg(rec.streams[d].quat, yaw(t))
        assert np.median(err) < 5 and err.max() < 20, (d, np.median(err), err.max())


def test_hands_without_orientations_face_the_heads_heading(tmp_path):
    from fixtures_recordings import write_wide_poses
    t, pos, quat = walking_take()
    path = write_wide_poses(tmp_path / "take.csv", t, pos, quat,
                            {"head": "hmd", "left_hand": "left_controller", "right_hand": "right_controller"}, "openxr")
    lines = open(path).read().splitlines()
    header = lines[0].split(",")
    keep = [i for i, c in enumerate(header) if "controller_rot" not in c]
    open(path, "w").write("\n".join(",".join(ln.split(",")[i] for i in keep) for ln in lines) + "\n")
    rec = formats.load_recording(path)
    assert "quaternions w,x,y,z; no orientation columns for left_hand, right_hand: level, facing the head's heading" \
        in rec.metadata["detected"]
    head_yaw = 0.2 * t + 0.25 * np.sin(2 * np.pi * 0.3 * t)
    assert _heading_error_deg(rec.streams["left_hand"].quat, head_yaw).max() < 0.1


@pytest.mark.parametrize("axes", ["unity", "openxr"])
def test_a_native_csv_without_axes_that_walks_backwards_is_warned_about(tmp_path, axes):
    """A native CSV that states no axes is read as OpenXR (its documented default); a Unity
    recording read so walks backwards, and the summary says what to do."""
    from blender_manikin.core.io_csv import read_csv, write_csv
    from blender_manikin.core.recording import Recording, TrackerStream
    t, pos, quat = walking_take()
    rec = Recording(streams={d: TrackerStream(d, t, pos[d], quat[d], np.ones(len(t), bool))
                             for d in ("head", "left_hand", "right_hand")}, source="walk", metadata={})
    stated = tmp_path / "stated.csv"
    write_csv(stated, rec, axes=axes)
    text = open(stated).read()
    (tmp_path / "unstated.csv").write_text(text.replace(f"# axes: {axes}\n", ""))
    warned = [w for w in read_csv(tmp_path / "unstated.csv").warnings if "no '# axes:' line" in w]
    if axes == "unity":
        assert len(warned) == 1 and "walks backwards 7.9 s more than forwards: a Unity recording?" in warned[0]
    else:
        assert warned == []
    assert not [w for w in read_csv(stated).warnings if "no '# axes:' line" in w]


@pytest.mark.parametrize("axes", ["unity", "openxr"])
def test_a_wide_csv_whose_time_column_holds_milliseconds_is_read_the_right_way(tmp_path, axes):
    """A logger that writes milliseconds under a plain ``time`` header: the walking direction still
    decides the axes (measured in seconds, not in a thousandth of the speed), where the hands at the
    sides alone would read the take mirrored."""
    from fixtures_recordings import write_wide_poses
    t, pos, quat = walking_take()
    names = {"head": "hmd", "left_hand": "left_controller", "right_hand": "right_controller"}
    path = write_wide_poses(tmp_path / "walk_ms.csv", t * 1000.0, pos, quat, names, axes)
    rec = formats.load_recording(path)
    line = rec.metadata["detected"]
    assert "time=time in ms" in line and f"axes {axes} (" in line and "from the walking direction (" in line, line
    np.testing.assert_allclose(rec.streams["head"].time, t, atol=1e-6)
    assert rec.metadata["layout"]["time"] == {"column": "time", "unit": "ms"}


@pytest.mark.parametrize("orientations", [True, False])
@pytest.mark.parametrize("axes", ["unity", "openxr"])
def test_repeated_rows_do_not_hide_the_walking_direction(tmp_path, axes, orientations):
    """A logger that writes some rows twice (the same time: two callbacks in one frame): the
    repeats are no step in time, so the walk still decides the axes, and quietly (no division by a
    zero time step on the console).  Read with the repeats, the walk vanished and, without
    orientation columns, the hands at the sides read the take mirrored."""
    import warnings
    from fixtures_recordings import write_wide_poses
    t, pos, quat = walking_take()
    names = {"head": "hmd", "left_hand": "left_controller", "right_hand": "right_controller"}
    path = write_wide_poses(tmp_path / "walk.csv", t, pos, quat, names, axes)
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    keep = [i for i, c in enumerate(header) if orientations or "_rot_" not in c]
    rows = [lines[0]] + [ln for k, ln in enumerate(lines[1:]) for _ in range(2 if k % 10 == 3 else 1)]
    path.write_text("\n".join(",".join(r.split(",")[i] for i in keep) for r in rows) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = formats.load_recording(path)
    line = rec.metadata["detected"]
    assert f"axes {axes} (" in line and "from the walking direction (" in line, line
