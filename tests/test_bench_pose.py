"""The pose benchmark's per-class breakdown (the benchmark itself needs ../shared's data)."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks"))

import bench_pose as bp  # noqa: E402


def test_motion_class_from_cache_file_names():
    assert bp.motion_class("/c/hdm05-subset_amc_HDM_bd_depositFloorR_001_120.amc-182c5b6a.npz") == "depositFloorR"
    assert bp.motion_class("hdm05-subset_amc_HDM_mm_squat1Reps_003_120.amc-0.npz") == "squat"
    assert bp.motion_class("Bandai-Namco-Research-Motiondataset-1_data_dataset-1_walk-turn-left_active_001-6.npz") \
        == "walk-turn-left"
    assert bp.motion_class("take_07.npz") == "other"


def test_class_table_is_frame_weighted_and_sorted_worst_first(capsys):
    prev = "(p) MANIKIN, previous model"
    r = {"name": "hdm05", "body": "calibrated", "by_class": {
        "squat": {"clips": 2, "frames": 100, (bp.SHIPPED, "MPJPE"): 500.0, (bp.SHIPPED, "L-PE"): 800.0,
                  (prev, "MPJPE"): 600.0, (prev, "L-PE"): 900.0},
        "kick": {"clips": 1, "frames": 50, (bp.SHIPPED, "MPJPE"): 700.0, (bp.SHIPPED, "L-PE"): 1000.0,
                 (prev, "MPJPE"): 650.0, (prev, "L-PE"): 950.0}}}
    bp.print_class_table(r)
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("| ")]
    assert lines[0].split("|")[1].strip() == "class"
    kick, squat = lines[1], lines[2]                     # kick's 14 cm first, squat's 5 cm next
    assert [c.strip() for c in kick.split("|")[1:-1]] == ["kick", "1", "50", "14.00", "20.00", "13.00", "19.00"]
    assert [c.strip() for c in squat.split("|")[1:-1]] == ["squat", "2", "100", "5.00", "8.00", "6.00", "9.00"]


def _moving_targets(T=90, fps=30.0):
    """Head and hands on smooth paths (metres, Z-up), each turning about Z: ``TrackerTargets``."""
    import numpy as np
    from blender_manikin.core import rotations as rot
    from blender_manikin.core.pose_result import TrackerTargets
    t = np.arange(T) / fps
    pos, rotm = {}, {}
    for k, d in enumerate(("head", "left_hand", "right_hand")):
        pos[d] = np.stack([0.3 * np.sin(t + k), 0.2 * np.cos(0.7 * t), 1.2 + 0.1 * np.sin(2 * t + k)], -1)
        rotm[d] = rot.axis_angle_to_matrix(np.stack([0 * t, 0 * t, 0.8 * np.sin(t + k)], -1))
    return TrackerTargets(fps=fps, pos=pos, rot=rotm)


def test_capture_without_noise_reproduces_the_targets():
    import numpy as np
    from blender_manikin.core import rotations as rot
    tg = _moving_targets()
    cap = bp.parse_capture("72,0,0,0")
    out, T = bp.captured_targets(tg, cap, seed=[0, 1])
    assert 88 <= T <= 90 and out.fps == tg.fps
    for d in tg.pos:
        assert np.abs(out.pos[d] - tg.pos[d][:T]).max() < 2e-3          # linear resampling of a smooth path
        ang = np.degrees(rot.geodesic_angle(out.rot[d], tg.rot[d][:T]))
        assert ang.max() < 0.5


def test_capture_noise_has_the_asked_size_and_is_shared_between_tracker_sets():
    import numpy as np
    tg = _moving_targets(T=900)
    cap = bp.parse_capture("72,5,0,0")
    a, T = bp.captured_targets(tg, cap, seed=[0, 3])
    b, _ = bp.captured_targets(tg, cap, seed=[0, 3])
    c, _ = bp.captured_targets(tg, cap, seed=[0, 4])
    err = a.pos["head"] - tg.pos["head"][:T]
    # 72 Hz noise read back at 30 fps by linear interpolation: σ between 5/√2 and 5 mm
    assert 3.0 < 1000 * err.std() < 5.5
    assert np.array_equal(a.pos["left_hand"], b.pos["left_hand"])
    assert not np.allclose(a.pos["left_hand"], c.pos["left_hand"])


def test_capture_argument_errors_name_the_field():
    import pytest
    assert bp.parse_capture("") is None
    assert bp.parse_capture("90") == {"rate": 90.0, "pos_mm": 2.0, "rot_deg": 0.5, "time_ms": 1.0}
    for bad, word in (("0", "rate"), ("72,x", "pos_mm"), ("72,1,-1", "rot_deg"), ("72,1,1,1,1", "at most")):
        with pytest.raises(SystemExit, match=word):
            bp.parse_capture(bad)


def test_tpose_body_is_what_the_calibration_builds_from_the_performer_standing_in_a_tpose():
    """--body tpose: the performer's skeleton stood in its rest T-pose and calibrated by the
    add-on's own calibration: a body-model performer gets its own stature and span back, another
    skeleton roughly what the skeleton-based estimate (--body calibrated) gives; with a pelvis
    tracker the legs are measured from it, as calibrated_body(legs=True) sizes them."""
    import numpy as np
    from blender_manikin.core import calibration as cal, skeleton as sk
    from standing import bandai_like_body
    J = sk.J
    me = sk.make_body(1.80)
    b = bp.tpose_calibration(me)[0]
    rest = me.rest_positions()
    span = np.linalg.norm(rest[J["left_wrist"]] - rest[J["right_wrist"]])
    # the span measured, plus the reach margin body_for gives each arm
    assert abs(b.stature - 1.80) < 0.01 and abs(b.measurements.arm_span - span - 2 * cal.REACH_MARGIN) < 0.005
    other = bandai_like_body(1.70)
    t, c = bp.tpose_calibration(other)[0], bp.calibrated_body(other)
    assert abs(t.stature / c.stature - 1.0) < 0.03
    assert abs(t.measurements.arm_span - c.measurements.arm_span - 2 * cal.REACH_MARGIN) < 0.005
    legs = bp.tpose_calibration(other, ("head", "left_hand", "right_hand", "pelvis"))[0]
    ref = bp.calibrated_body(other, legs=True)
    for k in ("thigh", "shank"):
        assert abs(getattr(legs.measurements, k) - getattr(ref.measurements, k)) < 0.02, k
    assert "tpose" in bp.BODY_MODES and set(bp.BODY_TITLES) == set(bp.BODY_MODES)


def test_tpose_offsets_put_the_foot_targets_where_the_calibrated_body_has_its_ankles():
    """--body tpose with foot trackers: the calibration measures the pelvis and foot trackers'
    offsets whole, so once applied (with_offsets) the ankle targets of the standing performer sit
    at the calibrated body's ankle height, even where the performer's own skeleton puts its
    ankles elsewhere; the head and hands keep their positions."""
    import numpy as np
    from blender_manikin.core import skeleton as sk
    from standing import bandai_like_body, standing_targets
    J = sk.J
    devices = ("head", "left_hand", "right_hand", "pelvis", "left_foot", "right_foot")
    other = bandai_like_body(1.70)
    body, offsets = bp.tpose_calibration(other, devices)
    raw = standing_targets(other, "T", devices=devices)
    out = bp.with_offsets(raw, offsets)
    rest = body.rest_positions()
    own = other.rest_positions()
    for side in ("left", "right"):
        want = rest[J[f"{side}_ankle"], 2]
        assert abs(own[J[f"{side}_ankle"], 2] - want) > 0.02                 # the skeletons differ...
        assert np.abs(out.pos[f"{side}_foot"][:, 2] - want).max() < 0.01     # ...the targets follow the body
    for d in ("head", "left_hand", "right_hand"):
        assert np.abs(out.pos[d] - raw.pos[d]).max() < 1e-9
    same = bp.with_offsets(raw, "none")
    assert all(np.array_equal(same.pos[d], raw.pos[d]) and np.allclose(same.rot[d], raw.rot[d]) for d in devices)


def test_head_body_sizes_each_clip_by_its_standing_head_height(monkeypatch):
    """--body head: each clip is solved with the body a recording without a calibration pose
    gets (core.solve.body_from_head_height of the clip's own trackers), whatever its skeleton;
    two clips of one performer standing at different heights get different bodies."""
    import argparse
    import numpy as np
    from blender_manikin.core import skeleton as sk
    from blender_manikin.core.solve import body_from_head_height
    performer = sk.make_body(1.80)
    clips = {}
    for name, dz in (("a_walk_000.npz", 0.0), ("b_walk_001.npz", -0.10)):
        T = 40
        local = np.tile(np.eye(3), (T, sk.NUM_JOINTS, 1, 1))
        root = np.tile(performer.root_rest + [0.0, 0.0, dz], (T, 1))
        pos, world = sk.forward_kinematics(local, root, performer)
        clips[name] = (performer, local, np.asarray(pos), np.asarray(world), 30.0, np.ones((T, 2), bool))
    monkeypatch.setattr(bp, "dataset_files", lambda name, max_clips=0: (list(clips), "fake"))
    monkeypatch.setattr(bp, "load_clip_with_contacts", lambda f: clips[f])
    seen = []

    def method(targets, body):
        seen.append((targets, body))
        from blender_manikin.core import baselines
        return baselines.classic_ik(targets, body)
    args = argparse.Namespace(max_clips=0, capture=None, smoothing=0.0, markdown=True, repeats=1)
    r = bp.run_dataset("hdm05", {"(c) classic IK": method}, args, "head")
    assert r["clips"] == 2 and r["body"] == "head"
    first, second = seen[0], seen[1]                  # the two clips (the timed runs come after)
    for targets, body in (first, second):
        assert body.stature == body_from_head_height(targets).stature
    assert abs(first[1].stature - 1.80) < 0.01                     # stood at its own height
    assert abs(first[1].stature - second[1].stature - 0.10 / sk.PROPORTIONS["head_height"]) < 1e-6
    assert "head" in bp.BODY_MODES and set(bp.BODY_TITLES) == set(bp.BODY_MODES)


def test_your_own_mocap_is_a_dataset(tmp_path, monkeypatch, capsys):
    """``--datasets PATH``: a folder of another studio's BVH takes (here Bandai-layout clips of a
    synthetic body) is cached, solved and tabled like the named sets; a sources .json names it;
    a path that is not there is an error naming the choices."""
    import json
    import pytest
    from fixtures_bvh import bandai_clip, synthetic_motion, write_fixture
    monkeypatch.setenv("BLENDER_MANIKIN_CACHE", str(tmp_path / "cache"))
    studio = tmp_path / "studio_b"
    studio.mkdir()
    for k in range(2):
        body, _, _, pos, rot = synthetic_motion(frames=60, seed=k)
        write_fixture(studio / f"take_{k}.bvh", bandai_clip(body, pos, rot, name=f"take_{k}"))
    sources = tmp_path / "sources.json"
    sources.write_text(json.dumps([{"path": str(studio), "name": "Studio B", "joint_map": "bandai"}]))
    # the caches built here in-process: this test process has threads (earlier tests' ONNX sessions),
    # where the benchmark's own worker processes would fork
    from blender_manikin.training import dataset
    for src in (dataset.MotionSource(path=str(studio)), dataset.load_sources(str(sources))[0]):
        dataset.build_cache(src, workers=1, verbose=False)
    argv = ["--body", "gt", "--trackers", "none", "--markdown", "--repeats", "1", "--previous-model", "none"]
    bp.main(["--datasets", str(studio)] + argv)
    out = capsys.readouterr().out
    assert "studio_b, true skeleton: 2 clips" in out
    row = next(ln for ln in out.splitlines() if ln.startswith("| (a) MANIKIN"))
    mpjpe = float(row.split("|")[2])
    assert 0.0 < mpjpe < 30.0                     # measured, finite: a pose, not a blow-up
    bp.main(["--datasets", str(sources)] + argv)
    assert "Studio B, true skeleton: 2 clips" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="unknown dataset 'nowhere'.*BVH / ASF-AMC"):
        bp.main(["--datasets", "nowhere"] + argv)


def test_a_dual_attention_poser_row_names_its_backbone():
    # a DAP model given as --previous-model was labelled "(p) MANIKIN, previous model"
    from types import SimpleNamespace
    dap = SimpleNamespace(contract=SimpleNamespace(arch="dap"),
                          path="/x/benchmarks/models/manikin_dap.onnx")
    assert bp.row_label(bp.PREVIOUS_ROW, dap) == "(p) MANIKIN, Dual Attention Poser (manikin_dap.onnx)"
    assert bp.row_label(bp.SHIPPED, dap) == "(a) MANIKIN, Dual Attention Poser (manikin_dap.onnx)"
    posenet = SimpleNamespace(contract=SimpleNamespace(arch="posenet"), path="/m/s.onnx")
    assert bp.row_label(bp.PREVIOUS_ROW, posenet) == "(p) MANIKIN, previous model"
