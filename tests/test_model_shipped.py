"""The shipped ONNX pose network: contract, size, and what inference guarantees.

Runs the real model (blender_manikin/models/manikin_s.onnx) through
onnxruntime on the bundled example recording, which is committed and made by
examples/make_example_recording.py (no ../shared needed).
"""
import os

import numpy as np
import pytest

from blender_manikin.core import calibration, device_offsets, features, metrics, pipeline
from blender_manikin.core import skeleton as sk
from blender_manikin.core.io_csv import read_csv
from blender_manikin.core.model_runner import DEFAULT_MODEL, ModelRunner
from blender_manikin.core.resample import resample

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


@pytest.fixture(scope="module")
def runner():
    assert os.path.isfile(DEFAULT_MODEL), "the trained model must be committed"
    return ModelRunner(DEFAULT_MODEL)


@pytest.fixture(scope="module")
def example():
    rec = read_csv(EXAMPLE)
    times, pos, quat, valid, report = resample(rec, 60.0)
    offsets = device_offsets.get_preset("openxr_generic")
    targets = device_offsets.to_targets(times, pos, quat, valid, offsets, fps=60.0)
    cand = calibration.find_tpose(targets, t0=float(times[0]))
    cal = calibration.calibrate(targets, time=cand.time, offsets=offsets, t0=float(times[0]))
    targets = device_offsets.to_targets(times, pos, quat, valid, cal.offsets, fps=60.0)
    return targets, calibration.body_for(cal.measurements), cal.offsets


def test_model_file_and_contract_match_the_code(runner):
    c = runner.contract
    assert os.path.getsize(DEFAULT_MODEL) <= 10 * 1024 * 1024
    assert c.kind == "manikin" and c.devices == features.INPUT_DEVICES
    # conditioned on the performer's proportions
    assert c.body and tuple(c.raw["body_features"]) == features.BODY_FEATURES
    assert c.input_dim == features.input_dim(body=True) and c.output_dim == features.output_dim("manikin")
    sources = c.raw["training_data"]["sources"]
    assert sources and all(src.get("licence") for src in sources)
    assert [tuple(b) for b in c.raw["output_blocks"]] == [tuple(b) for b in features.OUTPUT_BLOCKS["manikin"]]
    assert tuple(c.raw["joint_names"]) == sk.JOINT_NAMES
    assert c.raw["opset"] >= 17
    assert 0 < runner.num_parameters <= 2_000_000
    assert "CC BY-NC-ND" in c.raw["licence"]
    x = np.zeros((2, c.window, c.input_dim), np.float32)
    y = runner.predict(x)
    assert y.shape == (2, c.window, c.output_dim) and np.isfinite(y).all()


@pytest.mark.parametrize("name", ["pelvis", "six"])
def test_tracker_set_models_are_shipped_with_their_devices(name):
    """The four- and six-tracker networks: the same kind of contract as the three-tracker one,
    their devices listed (issue 14), within the same size budget.  Each model's window is its own
    (the three-tracker network was widened to 60 frames; the pipeline reads it from the contract)."""
    from blender_manikin.core import model_choice
    path = model_choice.shipped_model_path(name)
    assert os.path.isfile(path), f"the {name} model must be committed"
    assert os.path.getsize(path) <= 10 * 1024 * 1024
    r = ModelRunner(path)
    c = r.contract
    assert c.kind == "manikin" and c.devices == model_choice.SHIPPED_MODELS[name][1]
    assert c.body and c.input_dim == features.input_dim(c.devices, body=True)
    assert "CC BY-NC-ND" in c.raw["licence"] and 0 < r.num_parameters <= 2_000_000
    assert c.window >= 2 and c.raw["centre_frame"] == c.window // 2


def test_inference_hands_on_trackers_and_feet_above_floor(runner, example):
    targets, body, offsets = example
    res = pipeline.solve(targets, body, runner)
    pos = res.positions
    T = targets.num_frames
    assert pos.shape == (T, 22, 3) and np.isfinite(pos).all()
    for dev, j in (("left_hand", sk.J["left_wrist"]), ("right_hand", sk.J["right_wrist"])):
        err = np.linalg.norm(pos[:, j] - targets.pos[dev], axis=-1)
        assert err.max() < 1e-4, (dev, err.max(), int(np.argmax(err)))          # < 0.1 mm, every frame
    assert np.abs(pos[:, sk.J["head"]] - targets.pos["head"]).max() < 1e-6
    assert res.at_limit.shape == (T, 4) and res.at_limit.dtype == bool
    assert metrics.ground_penetration(pos) < 1e-7                               # cm
    assert pos[..., 2].min() > -1e-9
    ank = [sk.J["left_ankle"], sk.J["right_ankle"]]                           # no foot sinks in
    assert pipeline.feet_below_floor(pos[:, ank], res.world_rot[:, ank], body).max() <= pipeline.FOOT_SINK + 1e-6
    # planted feet do not slide: between two planted frames the ankle moves < 1 mm horizontally
    for k, ankle in enumerate((sk.J["left_ankle"], sk.J["right_ankle"])):
        both = res.contacts[:-1, k] & res.contacts[1:, k]
        step = np.linalg.norm(np.diff(pos[:, ankle, :2], axis=0), axis=-1)
        assert both.any() and step[both].max() < 1e-3


def test_solve_is_deterministic_and_any_fps(runner, example):
    targets, body, offsets = example
    a = pipeline.solve(targets, body, runner)
    b = pipeline.solve(targets, body, runner)
    assert np.array_equal(a.local_rot, b.local_rot)
    # the same recording at 24 fps gives the same pose at the shared instants (within interpolation)
    rec = read_csv(EXAMPLE)
    times, pos, quat, valid, _ = resample(rec, 24.0)
    t24 = device_offsets.to_targets(times, pos, quat, valid, offsets, fps=24.0)
    r24 = pipeline.solve(t24, body, runner)
    shared = np.arange(0, r24.num_frames, 2)              # 24 fps frame 2k == 60 fps frame 5k
    d = np.linalg.norm(r24.positions[shared] - a.positions[shared * 5 // 2], axis=-1)
    assert np.median(d) < 0.03


def test_arms_too_short_are_lengthened_from_the_reach(runner, example):
    """No calibration pose: arms from a too-short span miss the hands; the span the
    recording's reach asks for (capped at +8 %) brings them back on the trackers."""
    targets, body, _ = example
    short = sk.make_body(sk.BodyMeasurements(stature=body.stature, arm_span=1.25))
    res = pipeline.solve(targets, short, runner)
    far_before = (res.reach_error[:, :2] > 0.005).any(1).sum()
    assert far_before > 0.02 * targets.num_frames
    assert any("out of reach" in n and "body size" in n for n in res.quality_notes())
    far, close = res.misses(0)
    assert np.array_equal(far | close, res.reach_error[:, 0] > 0.005) and far.sum() > close.sum()
    first = calibration.arm_span_for_reach(res)
    assert first is not None and first > 1.25
    new_body, again, span = calibration.adapt_arms_to_reach(res, lambda b: pipeline.solve(targets, b, runner))
    proportional = sk.make_body(body.stature).rest_positions()
    cap = calibration.MAX_REACH_SPAN_FACTOR * np.linalg.norm(proportional[sk.J["left_wrist"]]
                                                             - proportional[sk.J["right_wrist"]])
    assert first <= span <= cap + 1e-9 and again.body is new_body
    assert (again.reach_error[:, :2] > 0.005).any(1).sum() < 0.1 * far_before
    # arms that reach are left alone
    assert calibration.arm_span_for_reach(pipeline.solve(targets, body, runner)) is None


def test_predicted_feet_are_never_reported_out_of_reach_but_foot_trackers_are(runner, example):
    """The network's ankles are no targets the performer set: a straight leg pointing at one a few
    millimetres too low is no body-size problem.  A foot tracker the leg cannot reach is."""
    targets, body, _ = example
    res = pipeline.solve(targets, body, runner)
    assert not any("foot" in n and "out of reach" in n for n in res.quality_notes()), res.quality_notes()
    assert np.all(res.reach_error[:, 2:] == 0.0)
    pos = res.positions
    feet = type(targets)(fps=targets.fps, pos=dict(targets.pos), rot=dict(targets.rot))
    for k, (dev, joint) in enumerate((("left_foot", "left_ankle"), ("right_foot", "right_ankle"))):
        feet.pos[dev] = pos[:, sk.J[joint]].copy()
        feet.rot[dev] = res.world_rot[:, sk.J[joint]].copy()
    feet.pos["left_foot"][30:40, 2] -= 0.25                   # the left tracker 25 cm below the ankle
    notes = pipeline.solve(feet, body, runner).quality_notes()
    assert any(n.startswith("left foot out of reach on") for n in notes), notes
    assert not any(n.startswith("right foot out of reach") for n in notes), notes


def test_hand_on_the_shoulder_is_reported_as_an_offset_problem(runner, example):
    targets, body, _ = example
    res0 = pipeline.solve(targets, body, runner)
    moved = type(targets)(fps=targets.fps, pos={d: v.copy() for d, v in targets.pos.items()},
                          rot=dict(targets.rot))
    f = slice(60, 90)
    moved.pos["right_hand"][f] = res0.positions[f, sk.J["right_shoulder"]] + [0.0, -0.03, -0.03]
    res = pipeline.solve(moved, body, runner)
    notes = res.quality_notes()
    assert any(n.startswith("right hand closer to the shoulder than the elbow can fold") and "device offsets" in n
               for n in notes), notes
    assert not any(n.startswith("right hand out of reach") for n in notes)
    # the collar swings the shoulder away first, so the hand misses by less than the fold limit
    from blender_manikin.core import limb_solver as ls
    l1, l2 = body.limb_lengths()[1]
    d_min = np.sqrt(l1 ** 2 + l2 ** 2 + 2 * l1 * l2 * np.cos(ls.FLEX_MAX[1]))
    miss = res.reach_error[f, 1]
    assert miss.max() < d_min - np.hypot(0.03, 0.03) - 0.02
    assert np.all(np.linalg.norm(res.positions[f, sk.J["right_wrist"]] - res.positions[f, sk.J["right_shoulder"]],
                                 axis=-1) >= d_min - 1e-6)
    # the same split, per frame: the moved frames are misses inside the fold, none out of reach
    far, close = res.misses(1)
    moved_frames = np.zeros(targets.num_frames, bool)
    moved_frames[f] = True
    assert np.array_equal(close, moved_frames & (res.reach_error[:, 1] > 0.005)) and close[f].all()
    assert not far.any()


def test_chunked_solve_equals_the_whole_take_solve(runner, example, monkeypatch):
    """Long takes are solved in pieces (network windows in batches, frames posed in chunks)
    to bound the memory; the result is the same, bit for bit, as in one piece."""
    targets, body, _ = example
    small = ModelRunner(DEFAULT_MODEL, batch=2)
    whole = pipeline.solve(targets, body, small, chunk_frames=10 ** 9)
    monkeypatch.setattr(pipeline, "NETWORK_WINDOWS_PER_BATCH", 2)
    parts = pipeline.solve(targets, body, small, chunk_frames=37)
    for k in ("local_rot", "root_pos", "swivel", "contacts", "reach_error", "at_limit"):
        np.testing.assert_array_equal(getattr(parts, k), getattr(whole, k), err_msg=k)
    # and re-assembling the same network output with the same body changes nothing
    again = whole.with_body(body)
    np.testing.assert_array_equal(again.local_rot, whole.local_rot)


def test_writers_in_chunks_write_the_same_files(runner, example, tmp_path, monkeypatch):
    from blender_manikin.core import export_json, formats, pose_result
    targets, body, _ = example
    res = pipeline.solve(targets, body, runner)
    written = {}
    for chunk in (10 ** 9, 13):
        monkeypatch.setattr(pose_result, "CHUNK_FRAMES", chunk)
        for fmt in ("json", "bvh", "npz"):
            path = tmp_path / f"{chunk}.{fmt}"
            formats.WRITERS[fmt].write(str(path), res, source="x", options=None)
            written.setdefault(fmt, []).append(path)
    for fmt in ("json", "bvh"):
        a, b = (p.read_bytes() for p in written[fmt])
        assert a == b, fmt
    a, b = (np.load(p) for p in written["npz"])
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    doc = export_json.read_json(written["json"][1])
    assert export_json.validate_document(doc) == []
    np.testing.assert_allclose(doc["positions"], res.positions, atol=1e-6)


def _mirror_image(targets):
    """The left/right mirror image (x -> -x) of tracker targets."""
    from blender_manikin.core.pose_result import TrackerTargets
    M = sk.MIRROR_M
    name = sk.mirror_name
    return TrackerTargets(fps=targets.fps, pos={name(d): p * [-1.0, 1, 1] for d, p in targets.pos.items()},
                          rot={name(d): M @ r @ M for d, r in targets.rot.items()},
                          valid={name(d): v for d, v in targets.valid.items()})


def test_mirrored_windows_make_the_network_stage_mirror_symmetric(runner, example):
    """mirror="both": the network stage of the mirrored recording is the mirror image of the
    original's, which the network alone is not.  "alternate" (the default) feeds every second
    window mirrored and keeps the others."""
    targets, body, _ = example
    M = sk.MIRROR_M

    def asymmetry(a, b):
        return max(np.abs(b.root_rot - M @ a.root_rot @ M).max(),
                   np.abs(b.torso_rot - M @ a.torso_rot[:, [0, 1, 2, 3, 5, 4]] @ M).max(),
                   np.abs(b.ankle_pos - a.ankle_pos[:, ::-1] * [-1.0, 1, 1]).max(),
                   np.abs(b.ankle_rot - M @ a.ankle_rot[:, ::-1] @ M).max(),
                   np.abs(np.exp(1j * b.swivel) - np.exp(-1j * a.swivel[:, [1, 0, 3, 2]])).max(),
                   np.abs(b.contact - a.contact[:, ::-1]).max())

    mirrored = _mirror_image(targets)
    both = [pipeline.run_network(t, body, runner, mirror="both") for t in (targets, mirrored)]
    off = [pipeline.run_network(t, body, runner, mirror="off") for t in (targets, mirrored)]
    assert asymmetry(*both) < 1e-4 < 0.01 < asymmetry(*off)

    class Recorder:
        def __init__(self):
            self.contract, self.batch, self.x = runner.contract, runner.batch, []

        def predict(self, x):
            self.x.append(x.copy())
            return runner.predict(x)
    seen = {}
    for mode in ("off", "alternate"):
        rec = Recorder()
        pipeline.run_network(targets, body, rec, mirror=None if mode == "alternate" else mode)   # None: the default
        seen[mode] = np.concatenate(rec.x)
    assert pipeline.MIRROR_WINDOWS == "alternate" and len(seen["off"]) >= 4
    with pytest.raises(ValueError, match="mirror 'sideways'"):
        pipeline.run_network(targets, body, runner, mirror="sideways")

    np.testing.assert_array_equal(seen["alternate"][0::2], seen["off"][0::2])
    np.testing.assert_allclose(seen["alternate"][1::2], features.mirror_inputs(seen["off"][1::2]), atol=1e-6)

    # a model with a tracker on one side only has no mirror image: its windows all run plain
    import dataclasses
    from blender_manikin.core.pose_result import TrackerTargets
    one_sided = dataclasses.replace(runner.contract, devices=("head", "left_hand", "right_hand", "left_foot"))
    feet = TrackerTargets(fps=targets.fps, pos=dict(targets.pos, left_foot=targets.pos["head"] * [1.0, 1, 0]),
                          rot=dict(targets.rot, left_foot=targets.rot["head"]))
    plain = {}
    for mode in (None, "off"):
        rec = Recorder()
        rec.contract = one_sided
        rec.predict = lambda x, rec=rec: (rec.x.append(x.copy()),
                                          np.zeros(x.shape[:2] + (one_sided.output_dim,), np.float32))[1]
        pipeline.run_network(feet, body, rec, mirror=mode)
        plain[mode] = np.concatenate(rec.x)
    np.testing.assert_array_equal(plain[None], plain["off"])

    # neither does a model not trained on mirrored windows, unless asked to
    unmirrored = dataclasses.replace(runner.contract, raw=dict(runner.contract.raw, training_data={}))
    assert runner.contract.trained_mirrored and not unmirrored.trained_mirrored
    for mode in (None, "alternate"):
        rec = Recorder()
        rec.contract = unmirrored
        pipeline.run_network(targets, body, rec, mirror=mode)
        plain[mode] = np.concatenate(rec.x)
    np.testing.assert_array_equal(plain[None], seen["off"])
    np.testing.assert_array_equal(plain["alternate"], seen["alternate"])
