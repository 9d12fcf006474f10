"""Recording file → resample → pipeline.solve (analytic limbs) → keyed armature, checked in Blender.

The network is replaced by a neutral stand-in (upright torso, zero swivel)
unless the shipped model exists; the hands are placed by the exact analytic
limb solver either way, so the evaluated wrist bones must sit on the tracker
targets on every frame.
"""
import os
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.core import features, pipeline  # noqa: E402
from blender_manikin.blender import solve_job  # noqa: E402
from blender_manikin.core import limb_solver as ls  # noqa: E402
from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402
from blender_manikin.core.pose_result import PoseResult, TrackerTargets  # noqa: E402

from blender_util import write_recording_csv  # noqa: E402


class NeutralRunner:
    """Stand-in for the ONNX model: identity torso/root in the canonical frame, feet under the head."""

    def __init__(self, fps=30.0, window=16):
        self.contract = SimpleNamespace(kind="manikin", fps=fps, window=window,
                                        devices=features.INPUT_DEVICES, body=False)
        self.path = "<neutral>"

    def predict(self, x):
        sl = features.output_slices("manikin")
        B, W = x.shape[:2]
        y = np.zeros((B, W, features.output_dim("manikin")), np.float32)
        eye6 = np.array([1, 0, 0, 0, 1, 0], np.float32)
        y[..., sl["root_rot"]] = eye6
        y[..., sl["torso_rot"]] = np.tile(eye6, len(features.TORSO_LOCAL))
        y[..., sl["ankle_pos"]] = [0.05, 0, -0.87, -0.05, 0, -0.87]
        y[..., sl["ankle_rot"]] = np.tile(eye6, 2)
        y[..., sl["swivel"]] = np.tile([1.0, 0.0], 4)
        y[..., sl["contact"]] = -5.0
        return y


def upright_motion(T=45, fps=30.0, seed=4):
    """Upright torso turning about Z, arms moving (elbows bent), head looking ahead."""
    rng = np.random.default_rng(seed)
    body = sk.make_body(1.78)
    t = np.arange(T) / fps
    local = np.broadcast_to(np.eye(3), (T, sk.NUM_JOINTS, 3, 3)).copy()
    local[:, 0] = rot.axis_angle_rotation(np.tile([0.0, 0, 1], (T, 1)), 0.6 * np.sin(t))
    for li, (_, b, m, e) in enumerate(sk.LIMBS[:2]):
        ph = rng.uniform(0, 6, 3)
        aa = np.stack([0.5 * np.sin(2 * t + ph[0]), 0.6 * np.sin(1.3 * t + ph[1]), 0.4 * np.sin(t + ph[2])], -1)
        local[:, b] = rot.axis_angle_to_matrix(aa)
        local[:, m] = rot.axis_angle_rotation(np.tile(ls.H0[li], (T, 1)), 0.9 + 0.5 * np.sin(3 * t + li))
        local[:, e] = rot.axis_angle_to_matrix(np.stack([0.2 * np.sin(t), 0 * t, 0.3 * np.cos(t)], -1))
    root = body.root_rest + np.stack([0.2 * t, -0.1 * t, 0 * t], -1)
    res = PoseResult(fps=fps, body=body, local_rot=local, root_pos=root, swivel=np.zeros((T, 4)), t0=3.0)
    pos, wr = res.fk()
    devs = {"head": "head", "left_hand": "left_wrist", "right_hand": "right_wrist"}
    res.targets = TrackerTargets(fps=fps, pos={d: pos[:, sk.J[j]] for d, j in devs.items()},
                                 rot={d: wr[:, sk.J[j]] for d, j in devs.items()})
    return res


def _solve(path, stature):
    sc = bpy.context.scene
    sc.render.fps, sc.render.fps_base = 30, 1.0
    s = sc.manikin
    s.source, s.filepath = 'FILE', str(path)
    s.calibration, s.height = 'MEASURE', stature
    s.create_trackers = True
    assert bpy.ops.manikin.solve_full_body() == {'FINISHED'}
    return s.armature


def _check_wrists(obj, T):
    sc = bpy.context.scene
    worst = 0.0
    for k in range(T):
        sc.frame_set(1 + k)
        mw = np.array(obj.matrix_world)
        for dev, joint in (("left_hand", "left_wrist"), ("right_hand", "right_wrist")):
            h = mw @ np.append(np.array(obj.pose.bones[joint].head), 1.0)
            target = np.array(bpy.data.objects[f"MANIKIN_{dev}"].matrix_world)[:3, 3]
            worst = max(worst, float(np.max(np.abs(h[:3] - target))))
    return worst


def test_wrists_on_targets_every_frame(addon, tmp_path, monkeypatch):
    res = upright_motion()
    path = write_recording_csv(tmp_path / "arms.csv", res, jitter=0.001, rates={"head": 90.0})
    monkeypatch.setattr(solve_job, "run_solver",
                        lambda t, b, progress=None: pipeline.solve(t, b, runner=NeutralRunner(),
                                                                   progress=progress))
    obj = _solve(path, 1.78)
    T = res.num_frames
    assert len(obj.animation_data.action.name) and bpy.context.scene.frame_end == T
    assert _check_wrists(obj, T) < 1e-4
    # the torso is reproduced (same body, upright stand-in torso); the elbows are not
    # compared: their swivel comes from the (stand-in) network
    sc = bpy.context.scene
    sc.frame_set(1 + T // 2)
    mw = np.array(obj.matrix_world)
    for j in (sk.J["pelvis"], sk.J["right_shoulder"], sk.J["head"]):
        h = mw @ np.append(np.array(obj.pose.bones[sk.JOINT_NAMES[j]].head), 1.0)
        assert np.max(np.abs(h[:3] - res.positions[T // 2, j])) < 1e-3


def test_shipped_model(addon, tmp_path):
    from blender_manikin.core import model_runner
    assert os.path.isfile(model_runner.DEFAULT_MODEL), "the shipped pose model is missing"
    res = upright_motion(T=60)
    path = write_recording_csv(tmp_path / "arms.csv", res)
    obj = _solve(path, 1.78)
    assert _check_wrists(obj, 60) < 1e-4


def test_job_lengthens_short_proportional_arms_and_says_so():
    """Measured height only (no arm span, no T-pose used) and too short for the performer's
    reach: the job re-solves with arms from the recording's reach and notes it."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    cfg = solve_job.SolveConfig(source='FILE', filepath=os.path.join(root, "examples", "example_recording.csv"),
                                fps=30.0, calibration='MEASURE', height=1.45)
    job = solve_job.SolveJob(cfg)
    job.compute()
    notes = [n for n in job.info if n.startswith("arm span")]
    assert len(notes) == 1 and "arm span" in job.summary()
    assert job.body is job.result.body and job.body.stature == pytest.approx(1.45)
    assert (job.result.reach_error[:, :2] > 0.005).any(1).mean() < 0.02
    # a given arm span is the user's word: never changed
    cfg2 = solve_job.SolveConfig(source='FILE', filepath=cfg.filepath, fps=30.0, calibration='MEASURE',
                                 height=1.45, arm_span=1.2)
    job2 = solve_job.SolveJob(cfg2)
    job2.compute()
    assert not any(n.startswith("arm span") for n in job2.info)
