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
