"""Every input format through the real add-on and the shipped model (issue: the add-on, Tests).

A natural upright motion of a known body is written as (a) native CSV in Unity
axes with jittered per-device rates, (b) native CSV in OpenXR axes with a
0.3 s gap in one hand, flipped quaternion signs and valid=0 rows, and (c) a
BeatLeader .bsor replay; each is imported, solved by the operator with the
shipped network, and the evaluated wrist bones must sit on the tracker
targets (the keyed tracker empties) within 0.1 mm on every frame.
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core.io_csv import write_csv  # noqa: E402
from blender_manikin.core.recording import TrackerStream, from_blender  # noqa: E402

from fixtures_recordings import bsor_bytes  # noqa: E402
from test_blender_pipeline import _check_wrists, _solve, upright_motion  # noqa: E402


def _streams(res, rates, jitter, seed=0):
    """Device samples of ``res.targets`` at their own rates (linear / slerp from the frame grid)."""
    rng = np.random.default_rng(seed)
    T = res.num_frames
    grid = res.t0 + np.arange(T) / res.fps
    out = {}
    for dev in res.targets.devices:
        rate = rates.get(dev, res.fps)
        n = int(np.floor((grid[-1] - grid[0]) * rate)) + 1
        t = grid[0] + np.arange(n) / rate + rng.normal(scale=jitter, size=n)
        t = np.clip(np.maximum.accumulate(t) + np.arange(n) * 1e-7, grid[0], grid[-1])
        t[0], t[-1] = grid[0], grid[-1]
        p = np.stack([np.interp(t, grid, res.targets.pos[dev][:, i]) for i in range(3)], -1)
        q = rot.quat_continuous(rot.matrix_to_quat(res.targets.rot[dev]))
        f = np.clip((t - grid[0]) * res.fps, 0, T - 1)
        i0 = np.minimum(np.floor(f).astype(int), T - 2)
        qs = rot.quat_slerp(q[i0], q[i0 + 1], f - i0)
        out[dev] = (t, p, qs)
    return out


def test_unity_axes_csv(addon, tmp_path):
    res = upright_motion(T=60)
    s = _streams(res, {"head": 90.0, "left_hand": 72.0, "right_hand": 120.0}, jitter=0.0015)
    path = tmp_path / "unity.csv"
    write_csv(path, [TrackerStream(d, t, p, q) for d, (t, p, q) in s.items()], axes="unity", precision=9)
    assert "# axes: unity" in path.read_text()[:400]
    obj = _solve(path, 1.78)
    assert _check_wrists(obj, 60) < 1e-4


def test_gap_flip_and_invalid_rows_csv(addon, tmp_path):
    res = upright_motion(T=60)
    s = _streams(res, {"head": 90.0, "left_hand": 90.0, "right_hand": 90.0}, jitter=0.001)
    streams = []
    for d, (t, p, q) in s.items():
        q = q.copy()
        valid = np.ones(len(t), bool)
        if d == "left_hand":
            keep = (t < res.t0 + 0.6) | (t > res.t0 + 0.9)          # 0.3 s of missing rows
            t, p, q, valid = t[keep], p[keep], q[keep], valid[keep]
            q[::7] *= -1.0                                             # sign flips
        if d == "right_hand":
            valid[40:46] = False                                       # tracking lost
            p[40:46] += 5.0                                            # garbage while invalid
        streams.append(TrackerStream(d, t, p, q, valid))
    path = tmp_path / "gap.csv"
    write_csv(path, streams, axes="openxr", precision=9)
    obj = _solve(path, 1.78)
    assert _check_wrists(obj, 60) < 1e-4
    # the bridged hand follows the interpolated target through the gap, not the garbage
    sc = bpy.context.scene
    sc.frame_set(1 + 40 * 30 // 90 + 1)
    w = np.array(obj.pose.bones["right_wrist"].head)
    assert np.linalg.norm(w - res.positions[40 * 30 // 90 + 1, 21]) < 0.05


def test_bsor_replay(addon, tmp_path):
    res = upright_motion(T=60)
    s = _streams(res, {}, jitter=0.0)
    t = s["head"][0] - s["head"][0][0]
    cols = []
    for d in ("head", "left_hand", "right_hand"):
        _, p, q = s[d]
        pu, qu = from_blender(p, q, "unity")
        cols.append(np.concatenate([pu, qu[:, 1:], qu[:, :1]], -1))
    path = tmp_path / "replay.bsor"
    path.write_bytes(bsor_bytes(t.astype(np.float32), *cols, frame_fps=30))
    assert bpy.context.scene.manikin.axes == 'AUTO'        # .bsor implies Unity axes
    bpy.context.scene.manikin.offsets_preset = 'none'      # the synthetic file holds joint poses
    obj = _solve(path, 1.78)
    assert _check_wrists(obj, 60) < 1e-4
