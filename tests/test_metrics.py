"""Hand-checked cases for blender_manikin.core.metrics."""
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from blender_manikin.core import metrics as M
from blender_manikin.core import rotations as rot
from blender_manikin.core.skeleton import J, NUM_JOINTS, forward_kinematics, make_body

FPS = 60.0


def _rest_sequence(T=10, body=None):
    """A standing T-pose repeated over T frames: positions and identity local rotations."""
    body = body or make_body(1.75)
    local = np.broadcast_to(np.eye(3), (T, NUM_JOINTS, 3, 3)).copy()
    root = np.broadcast_to(body.root_rest, (T, 3)).copy()
    pos, _ = forward_kinematics(local, root, body)
    return pos, local, body


def _random_pose_sequence(T, seed=0, body=None):
    rng = np.random.default_rng(seed)
    body = body or make_body(1.75)
    local = rot.axis_angle_to_matrix(rng.normal(scale=0.3, size=(T, NUM_JOINTS, 3)))
    root = body.root_rest + rng.normal(scale=0.01, size=(T, 3))
    pos, _ = forward_kinematics(local, root, body)
    return pos, local, body


# --------------------------------------------------------------------------
# joint sets
def test_joint_sets_partition_the_body_with_pelvis_in_the_upper_body():
    upper, lower = set(M.UPPER_JOINTS), set(M.LOWER_JOINTS)
    assert upper.isdisjoint(lower)
    assert upper | lower == set(range(NUM_JOINTS))
    assert len(upper) == 14 and len(lower) == 8
    assert J["pelvis"] in upper
    assert set(M.HAND_JOINTS) == {J["left_wrist"], J["right_wrist"]}
    # the MANIKIN / AvatarJLM evaluation index lists
    assert sorted(upper) == [0, 3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21]
    assert sorted(lower) == [1, 2, 4, 5, 7, 8, 10, 11]
    assert M.ROTATION_JOINTS == tuple(range(22))


# --------------------------------------------------------------------------
# hand-checked values
def test_zero_error_gives_zeros():
    pos, local, body = _random_pose_sequence(30)
    r = M.evaluate(pos, local, pos.copy(), local.copy(), FPS, body=body)
    for key in ("MPJRE", "MPJPE", "MPJVE", "H-PE", "U-PE", "L-PE"):
        assert r[key] == 0.0, key
    assert r["Bone-max"] < 1e-10 and r["Bone-mean"] < 1e-10
    assert r["Jitter"] == pytest.approx(r["Jitter-GT"])
    assert set(r) == set(M.UNITS)


def test_constant_1cm_offset():
    pos, local, body = _rest_sequence(12)
    pred = pos + np.array([0.0, 0.006, 0.008])          # |offset| = 1 cm
    r = M.evaluate(pred, local, pos, local, FPS, body=body)
    for key in ("MPJPE", "H-PE", "U-PE", "L-PE"):
        assert r[key] == pytest.approx(1.0, abs=1e-12), key
    assert r["MPJVE"] == pytest.approx(0.0, abs=1e-9)
    assert r["Jitter"] == pytest.approx(0.0, abs=1e-6)
    assert r["MPJRE"] == 0.0
    assert r["GP"] == 0.0                                # moved up: nothing below the floor
    assert r["Bone-max"] < 1e-10                         # a translation keeps bone lengths
    assert M.mpjpe(pred, pos) == pytest.approx(1.0)
    assert M.hand_pe(pred, pos) == pytest.approx(1.0)


def test_offset_on_the_hands_only():
    pos, local, _ = _rest_sequence(5)
    pred = pos.copy()
    pred[:, J["left_wrist"], 0] += 0.02                  # 2 cm on one wrist
    r = M.evaluate(pred, local, pos, local, FPS)
    assert r["H-PE"] == pytest.approx(1.0)               # mean of 2 cm and 0
    assert r["MPJPE"] == pytest.approx(2.0 / 22)
    assert r["U-PE"] == pytest.approx(2.0 / 14)
    assert r["L-PE"] == 0.0


def test_10_degree_rotation_on_one_joint():
    pos, local, _ = _rest_sequence(7)
    pred_rot = local.copy()
    pred_rot[:, J["left_elbow"]] = rot.axis_angle_to_matrix(np.radians(10.0) * rot.normalize([1.0, 2.0, -0.5]))
    assert M.mpjre(pred_rot, local) == pytest.approx(10.0 / 22, rel=1e-12)
    r = M.evaluate(pos, pred_rot, pos, local, FPS)
    assert r["MPJRE"] == pytest.approx(10.0 / 22, rel=1e-12)
    # restricted to that joint it is the full 10 degrees
    assert M.mpjre(pred_rot, local, joints=[J["left_elbow"]]) == pytest.approx(10.0)


def test_rotation_angle_matches_geodesic_angle_and_is_exact_at_zero():
    rng = np.random.default_rng(3)
    Ra = rot.axis_angle_to_matrix(rng.normal(size=(500, 3)))
    Rb = rot.axis_angle_to_matrix(rng.normal(size=(500, 3)))
    np.testing.assert_allclose(M.rotation_angle(Ra, Rb), rot.geodesic_angle(Ra, Rb), atol=1e-7)
    assert np.all(M.rotation_angle(Ra, Ra) == 0.0)
    # tiny and half-turn angles
    for angle in (1e-9, 1e-5, 0.3, math.pi - 1e-6, math.pi):
        R = rot.axis_angle_to_matrix(angle * rot.normalize([0.3, -1.0, 0.2]))
        assert M.rotation_angle(np.eye(3), R) == pytest.approx(angle, rel=1e-6, abs=1e-15)


def test_known_cubic_trajectory_gives_known_jitter():
    T = 50
    t = np.arange(T) / FPS
    a = np.array([1.0, 2.0, 2.0])                        # p = a t^3, jerk = 6 a, |6 a| = 18 m/s^3
    pos = np.broadcast_to(t[:, None, None] ** 3 * a, (T, NUM_JOINTS, 3)).copy()
    assert M.jitter(pos, FPS) == pytest.approx(18.0 / 100, rel=1e-6)
    # a quadratic has no jerk
    quad = np.broadcast_to(t[:, None, None] ** 2 * a, (T, NUM_JOINTS, 3)).copy()
    assert M.jitter(quad, FPS) == pytest.approx(0.0, abs=1e-6)
    # evaluate reports the prediction's jitter and the ground truth's separately
    r = M.evaluate(pos, None, quad, None, FPS)
    assert r["Jitter"] == pytest.approx(0.18, rel=1e-6)
    assert r["Jitter-GT"] == pytest.approx(0.0, abs=1e-6)
    assert math.isnan(r["MPJRE"])


def test_velocity_error_of_a_linear_drift():
    pos, local, _ = _rest_sequence(20)
    v = np.array([0.3, 0.0, 0.4])                        # 0.5 m/s = 50 cm/s
    drift = pos + (np.arange(20) / FPS)[:, None, None] * v
    assert M.mpjve(drift, pos, FPS) == pytest.approx(50.0, rel=1e-9)
    assert M.mpjve(drift, pos, 2 * FPS) == pytest.approx(50.0 * 2, rel=1e-9)


def test_ground_penetration():
    pos, _, _ = _rest_sequence(8)
    assert M.ground_penetration(pos) == 0.0              # rest pose stands on the floor
    low = pos.copy()
    low[:, J["left_foot"], 2] = -0.02                    # 2 cm below the floor
    assert M.ground_penetration(low) == pytest.approx(2.0)
    # only half the frames penetrate: the mean over frames halves
    half = pos.copy()
    half[:4, J["right_ankle"], 2] = -0.02
    assert M.ground_penetration(half) == pytest.approx(1.0)
    # only the lowest joint counts
    two = low.copy()
    two[:, J["right_foot"], 2] = -0.01
    assert M.ground_penetration(two) == pytest.approx(2.0)
    # other floor height
    assert M.ground_penetration(pos + [0, 0, 0.5], floor=0.53) == pytest.approx(
        100 * max(0.0, 0.53 - (pos[0, :, 2].min() + 0.5)))


def test_bone_length_drift():
    pos, local, body = _random_pose_sequence(6)
    assert M.bone_length_drift(pos, body.bone_lengths()) == pytest.approx((0.0, 0.0), abs=1e-10)
    root = pos[:, :1]
    scaled = root + 1.1 * (pos - root)                   # every bone 10 % longer
    L = body.bone_lengths()[1:]
    bmax, bmean = M.bone_length_drift(scaled, body.bone_lengths())
    assert bmax == pytest.approx(10.0 * L.max())         # 0.1 L metres = 10 L cm
    assert bmean == pytest.approx(10.0 * L.mean())
    assert M.bone_length_drift(scaled, L) == pytest.approx((bmax, bmean))
    # evaluate: against the body, or against the ground truth's own lengths
    r = M.evaluate(scaled, local, pos, local, FPS, body=body)
    assert (r["Bone-max"], r["Bone-mean"]) == pytest.approx((bmax, bmean))
    r = M.evaluate(scaled, local, pos, local, FPS)
    assert (r["Bone-max"], r["Bone-mean"]) == pytest.approx((bmax, bmean))


def test_too_few_frames_gives_nan_for_derivatives():
    pos, local, _ = _rest_sequence(3)
    assert math.isnan(M.jitter(pos, FPS))
    r = M.evaluate(pos[:1], local[:1], pos[:1], local[:1], FPS)
    assert math.isnan(r["MPJVE"]) and math.isnan(r["Jitter"])
    assert r["MPJPE"] == 0.0
    assert not math.isnan(M.mpjve(pos[:2], pos[:2], FPS))


def test_float32_input():
    pos, local, _ = _rest_sequence(6)
    pred = (pos + [0.01, 0, 0]).astype(np.float32)
    r = M.evaluate(pred, local.astype(np.float32), pos, local, FPS)
    assert r["MPJPE"] == pytest.approx(1.0, rel=1e-5)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2 ** 31 - 1), st.integers(1, 8))
def test_upper_and_lower_errors_average_to_mpjpe(seed, T):
    rng = np.random.default_rng(seed)
    gt = rng.normal(size=(T, NUM_JOINTS, 3))
    pred = gt + rng.normal(scale=0.05, size=gt.shape)
    r = M.evaluate(pred, None, gt, None, FPS)
    assert (14 * r["U-PE"] + 8 * r["L-PE"]) / 22 == pytest.approx(r["MPJPE"], rel=1e-12)
    e = np.linalg.norm(pred - gt, axis=-1) * 100
    assert r["MPJPE"] <= e.max() + 1e-12
    assert r["H-PE"] == pytest.approx(e[:, [20, 21]].mean())


# --------------------------------------------------------------------------
# validation
def test_shapes_are_validated():
    pos, local, _ = _rest_sequence(4)
    with pytest.raises(ValueError, match=r"pred_pos must have shape \(T, 22, 3\)"):
        M.evaluate(pos[:, :21], local, pos, local, FPS)
    with pytest.raises(ValueError, match="same shape"):
        M.evaluate(pos[:3], local[:3], pos, local, FPS)
    with pytest.raises(ValueError, match=r"pred_local_rot must have shape \(T, 22, 3, 3\)"):
        M.evaluate(pos, local[..., :2], pos, local, FPS)
    with pytest.raises(ValueError, match="frames"):
        M.evaluate(pos, local[:2], pos, local[:2], FPS)
    with pytest.raises(ValueError, match="both"):
        M.evaluate(pos, local, pos, None, FPS)
    with pytest.raises(ValueError, match="T >= 1"):
        M.mpjpe(pos[:0], pos[:0])
    with pytest.raises(ValueError, match=r"\(T, J, 3\)"):
        M.mpjpe(pos[0], pos[0])
    with pytest.raises(ValueError, match=r"\(T, J, 3\)"):
        M.jitter(pos.reshape(4, -1), FPS)
    with pytest.raises(ValueError, match="fps"):
        M.evaluate(pos, local, pos, local, 0)
    with pytest.raises(ValueError, match="fps"):
        M.mpjve(pos, pos, float("nan"))
    with pytest.raises(ValueError, match="fps"):
        M.jitter(pos, "fast")
    with pytest.raises(ValueError, match="ref_lengths"):
        M.bone_length_drift(pos, np.ones(5))
    with pytest.raises(ValueError, match="out of range"):
        M.mpjpe(pos, pos, joints=[22])


# --------------------------------------------------------------------------
# table
def test_format_table_is_aligned_markdown():
    rows = [("MANIKIN", {"MPJPE": 1.234, "H-PE": 0.0, "GP": float("nan"), "frames": 1200}),
            ("a much longer method name", {"MPJPE": 12.5, "note": "ok"})]
    text = M.format_table(rows, ["MPJPE", "H-PE", "GP", "frames", "note"])
    lines = text.splitlines()
    assert len(lines) == 4
    assert len({len(line) for line in lines}) == 1                  # aligned
    assert all(line.startswith("| ") and line.endswith(" |") for line in (lines[0], lines[2], lines[3]))
    assert lines[0].split("|")[1].strip() == "method"
    assert [c.strip() for c in lines[0].split("|")[2:-1]] == ["MPJPE", "H-PE", "GP", "frames", "note"]
    sep = lines[1].strip("|").split("|")
    assert set(sep[0]) == {"-"} and all(c.endswith(":") and set(c[:-1]) == {"-"} for c in sep[1:])
    cells = [c.strip() for c in lines[2].split("|")[1:-1]]
    assert cells == ["MANIKIN", "1.23", "0.00", "n/a", "1200", "-"]
    cells = [c.strip() for c in lines[3].split("|")[1:-1]]
    assert cells == ["a much longer method name", "12.50", "-", "-", "-", "ok"]
    # numbers right-aligned
    assert lines[2].split("|")[2].startswith(" ") and lines[2].split("|")[2].endswith("1.23 ")


def test_format_table_options():
    rows = [("x", {"MPJPE": 1.0, "rate": 123456.7})]
    text = M.format_table(rows, formats={"rate": ",.0f", "MPJPE": lambda v: f"{v:.1f}!"},
                          name_header="solver", units=True)
    header = [c.strip() for c in text.splitlines()[0].split("|")[1:-1]]
    assert header == ["solver", "MPJPE [cm]", "rate"]                 # default columns: first appearance
    cells = [c.strip() for c in text.splitlines()[2].split("|")[1:-1]]
    assert cells == ["x", "1.0!", "123,457"]
    # evaluate() output drops straight into a table
    pos, local, _ = _rest_sequence(5)
    r = M.evaluate(pos, local, pos, local, FPS)
    text = M.format_table([("gt", r)], M.PAPER_COLUMNS)
    assert len(text.splitlines()) == 3 and "MPJRE" in text


# --------------------------------------------------------------------------
# the solver benchmark uses the table and the rotation error; keep it runnable
def test_bench_solver_smoke(capsys):
    import importlib.util
    import os
    path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                        "benchmarks", "bench_solver.py")
    spec = importlib.util.spec_from_file_location("bench_solver", path)
    bench = importlib.util.module_from_spec(spec)
    saved = dict(os.environ)
    try:
        spec.loader.exec_module(bench)        # sets *_NUM_THREADS=1 for its own process
    finally:
        os.environ.clear()
        os.environ.update(saved)
    rows = bench.main(["--frames", "64", "--repeat", "1", "--chunks", "0,16"])
    out = capsys.readouterr().out
    assert "limb-solves/s" in out and "numpy" in out
    assert len(rows) == 8
    for name, r in rows:
        assert r["frames/s"] > 0
        if name.startswith("round trip"):
            # positions -> swivel -> solve -> FK reproduces the ends exactly
            assert r["wrist pos [m]"] < 1e-9 and r["ankle pos [m]"] < 1e-9
            assert r["wrist rot [deg]"] < 1e-8 and r["ankle rot [deg]"] < 1e-8
            assert r["elbow/knee pos [m]"] < 1e-5


def test_knee_flexion_angle():
    from blender_manikin.core import rotations as rot, skeleton as sk
    from blender_manikin.core.metrics import knee_flexion
    body = sk.make_body(1.75)
    T = 5
    local = np.tile(np.eye(3), (T, sk.NUM_JOINTS, 1, 1))
    ang = np.radians([0.0, 10.0, 45.0, 90.0, 120.0])
    local[:, sk.J["left_knee"]] = rot.axis_angle_rotation(np.array([1.0, 0, 0]), ang)
    P, _ = sk.forward_kinematics(local, np.tile(body.root_rest, (T, 1)), body)
    k = knee_flexion(P)
    assert np.allclose(k[:, 0], np.degrees(ang), atol=1e-6) and np.allclose(k[:, 1], 0.0, atol=1e-6)
