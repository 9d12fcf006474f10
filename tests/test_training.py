"""Training pipeline: torch geometry vs numpy, BVH -> cache -> windows -> train -> resume -> ONNX.

Needs torch and onnx (requirements-train.txt); skipped without them.  Uses
only synthetic BVH files written into tmp dirs (no /work/shared data) and a
tiny network, so the whole module runs in a few seconds on 2 cores.
"""
import dataclasses
import json
import os

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")

from blender_manikin.core import bvh, features, limb_solver as ls, rotations as rot, skeleton as sk  # noqa: E402
from blender_manikin.training import dataset as ds, losses, torch_geometry as tg  # noqa: E402
from blender_manikin.training.model import ModelConfig, PoseNet, count_parameters  # noqa: E402

TINY = ["--d-model", "32", "--heads", "2", "--layers", "1", "--head-hidden", "32", "--batch", "8",
        "--threads", "1", "--val-windows", "16", "--workers", "1", "--quiet", "--ckpt-minutes", "100"]


def _t(a):
    return torch.as_tensor(np.asarray(a, np.float64))


# --------------------------------------------------------------------------
# geometry
def test_sixd_and_rotation_between_match_numpy():
    rng = np.random.default_rng(0)
    d6 = rng.normal(size=(50, 3, 6))
    assert np.abs(tg.sixd_to_matrix(_t(d6)).numpy() - rot.sixd_to_matrix(d6)).max() < 1e-10
    R = rot.axis_angle_to_matrix(rng.normal(size=(20, 3)))
    assert np.abs(tg.matrix_to_6d(_t(R)).numpy() - rot.matrix_to_6d(R)).max() < 1e-12
    a = rng.normal(size=(40, 3))
    b = rng.normal(size=(40, 3))
    b[:5] = -a[:5] * 2.0           # antiparallel
    b[5:10] = a[5:10]              # parallel
    assert np.abs(tg.rotation_between(_t(a), _t(b)).numpy() - rot.rotation_between(a, b)).max() < 1e-10
    q = rng.normal(size=(30, 4))
    assert np.abs(tg.quat_to_matrix(_t(q)).numpy() - rot.quat_to_matrix(q)).max() < 1e-10


def _limb_case(rng, T=200):
    base = rng.normal(size=(T, 4, 3))
    end = base + rng.normal(size=(T, 4, 3)) * 0.35
    end[:5] = base[:5]                                                  # coincident
    end[5:10] = base[5:10] + rng.normal(size=(5, 4, 3)) * 3.0           # out of reach
    parent = rot.axis_angle_to_matrix(rng.normal(size=(T, 4, 3)))
    # base->end exactly against the neutral axis (u undefined): still finite
    end[10:15] = base[10:15] - 0.3 * np.einsum("tlij,lj->tli", parent[10:15], ls.N0)
    swivel = rng.uniform(-np.pi, np.pi, (T, 4))
    lengths = rng.uniform(0.2, 0.5, (T, 4, 2))
    return base, end, parent, swivel, lengths


def test_swivel_frame_and_mid_from_swivel_match_numpy():
    rng = np.random.default_rng(1)
    base, end, parent, swivel, lengths = _limb_case(rng)
    for got, ref in zip(tg.swivel_frame(_t(base), _t(end), _t(parent)), ls.swivel_frame(base, end, parent)):
        assert np.abs(got.numpy() - ref).max() < 1e-5
    ref = ls.mid_from_swivel(base, end, swivel, lengths, parent)
    got = tg.mid_from_swivel(_t(base), _t(end), _t(swivel), _t(lengths), _t(parent)).numpy()
    assert np.abs(got - ref).max() < 1e-5
    # (cos, sin) pairs of any scale give the same joint (the network's form)
    cs = np.stack([np.cos(swivel), np.sin(swivel)], -1) * rng.uniform(0.3, 3.0, (len(swivel), 4, 1))
    got = tg.mid_from_swivel(_t(base), _t(end), _t(cs), _t(lengths), _t(parent)).numpy()
    assert np.abs(got - ref).max() < 1e-5
    # a subset of limbs, float32
    got = tg.mid_from_swivel(_t(base[:, 2:]).float(), _t(end[:, 2:]).float(), _t(swivel[:, 2:]).float(),
                             _t(lengths[:, 2:]).float(), _t(parent[:, 2:]).float(), limb_ids=[2, 3]).numpy()
    assert np.abs(got - ls.mid_from_swivel(base[:, 2:], end[:, 2:], swivel[:, 2:], lengths[:, 2:],
                                           parent[:, 2:], limb_ids=[2, 3])).max() < 1e-5


def test_mid_from_swivel_gradients_finite():
    rng = np.random.default_rng(2)
    base, end, parent, swivel, lengths = _limb_case(rng, 60)
    end[15:20] = base[15:20] + np.array([lengths[15:20, :, 0] + lengths[15:20, :, 1]]).transpose(1, 2, 0) * \
        rot.normalize(rng.normal(size=(5, 4, 3)))                      # exactly straight
    ins = [_t(a).requires_grad_() for a in (base, end)]
    cs = _t(np.stack([np.cos(swivel), np.sin(swivel)], -1)).requires_grad_()
    out = tg.mid_from_swivel(ins[0], ins[1], cs, _t(lengths), _t(parent))
    out.sum().backward()
    for x in ins + [cs]:
        assert torch.isfinite(x.grad).all()


def test_torso_and_full_fk_match_numpy():
    rng = np.random.default_rng(3)
    B, W = 3, 5
    local = rot.axis_angle_to_matrix(rng.normal(size=(B, W, 22, 3)) * 0.6)
    offsets = np.stack([sk.make_body(h).offsets for h in (1.5, 1.7, 1.9)])      # per-sample bodies
    P = np.empty((B, W, 22, 3))
    R = np.empty((B, W, 22, 3, 3))
    for b in range(B):
        P[b], R[b] = sk.forward_kinematics(local[b], np.zeros((W, 3)), None, offsets=offsets[b])
    pos, wrot = tg.torso_fk(_t(local[:, :, 0]), _t(local[:, :, list(features.TORSO_LOCAL_IDX)]),
                            _t(offsets[:, None]))
    ref = P[:, :, list(tg.TORSO_FK_JOINTS)] - P[:, :, [sk.J["head"]]]
    assert np.abs(pos.numpy() - ref).max() < 1e-10
    for j, Rj in wrot.items():
        assert np.abs(Rj.numpy() - R[:, :, j]).max() < 1e-10
    fp, fr = tg.full_fk(_t(local[:, :, 0]), _t(local[:, :, 1:]), _t(offsets[:, None]))
    assert np.abs(fp.numpy() - P).max() < 1e-10
    assert np.abs(fr.numpy() - R).max() < 1e-10


# --------------------------------------------------------------------------
# data
@pytest.fixture(scope="module")
def bvh_dir(tmp_path_factory):
    """Six Bandai-layout takes at 30 fps and one CMU-layout take at 120 fps."""
    import sys
    sys.path.insert(0, os.path.dirname(__file__))
    from fixtures_bvh import bandai_clip, cmu_clip, synthetic_motion, write_fixture
    d = tmp_path_factory.mktemp("bvh")
    for i in range(6):
        body, _, _, pos, R = synthetic_motion(sk.make_body(1.6 + 0.05 * i), frames=90, fps=30.0, seed=i)
        write_fixture(str(d / f"dataset-t_walk_{i:03d}.bvh"), bandai_clip(body, pos, R, name=f"walk_{i:03d}"))
    body, _, _, pos, R = synthetic_motion(frames=240, fps=120.0, seed=7)
    write_fixture(str(d / "cmu_07_01.bvh"), cmu_clip(body, pos, R, name="cmu_07_01"))
    return str(d)


@pytest.fixture(scope="module")
def cache(bvh_dir, tmp_path_factory):
    root = str(tmp_path_factory.mktemp("cache"))
    files = ds.build_cache(bvh_dir, root, workers=2, verbose=False)
    return root, files


def test_cache_contents_and_split(cache):
    root, files = cache
    assert len(files) == 7 and all(f.startswith(root) and os.path.exists(f) for f in files)
    index, split = ds.load_index(files)
    assert index["frames"] == 6 * 90 + 60                    # the 120 fps take resampled to 30 fps
    with np.load(files[0]) as z:
        T = z["local_quat"].shape[0]
        assert z["local_quat"].dtype == np.float32 and z["local_quat"].shape == (T, 22, 4)
        assert z["root_pos"].shape == (T, 3) and z["swivel"].shape == (T, 4)
        assert z["contacts"].shape == (T, 2) and set(np.unique(z["contacts"])) <= {0, 1}
        assert z["offsets"].shape == (22, 3) and float(z["stature"]) > 1.0
        assert float(z["ik_error_max"]) < 0.02                  # the IK reproduces the mocap
    # the split holds out whole takes, deterministically
    names = {os.path.basename(f) for f in files}
    assert set(split["train"]) | set(split["val"]) == names and split["train"] and split["val"]
    tk = {c["file"]: c["take_id"] for c in index["clips"]}
    assert not {tk[f] for f in split["train"]} & {tk[f] for f in split["val"]}
    assert ds.make_split(index["clips"]) == split


def test_cache_reads_a_mixamo_take(tmp_path):
    """A Mixamo-rig BVH (as Blender writes it from Mixamo's FBX) is a training source: mapped by
    the hierarchy (it has every cgspeed name), its body measured, the IK reproducing it."""
    import sys
    sys.path.insert(0, os.path.dirname(__file__))
    from fixtures_bvh import mixamo_clip, synthetic_motion, write_fixture
    src = tmp_path / "mixamo"
    src.mkdir()
    body, _, _, pos, R = synthetic_motion(sk.make_body(1.83), frames=60, fps=30.0, seed=11)
    write_fixture(str(src / "Jumping.bvh"), mixamo_clip(body, pos, R, name="Jumping"))
    files = ds.build_cache(str(src), str(tmp_path / "cache"), workers=1, verbose=False)
    assert len(files) == 1
    with np.load(files[0]) as z:
        assert float(z["ik_error_max"]) < 0.02
        assert float(z["stature"]) == pytest.approx(1.83, abs=0.02)


def test_second_build_does_not_parse(cache, bvh_dir, monkeypatch):
    root, files = cache

    def boom(*a, **k):
        raise AssertionError("BVH read again")
    monkeypatch.setattr(bvh, "read_bvh", boom)
    monkeypatch.setattr(bvh, "iter_bvh_sources", boom)
    assert ds.build_cache(bvh_dir, root, verbose=False) == files


def test_foot_contacts_rule():
    P = np.zeros((30, 22, 3))
    P[:, :, 2] = 0.5
    P[:, [sk.J["left_ankle"], sk.J["left_foot"]], 2] = 0.05          # left stands still on the floor
    P[:, [sk.J["right_ankle"], sk.J["right_foot"]], 2] = 0.05
    P[:, [sk.J["right_ankle"], sk.J["right_foot"]], 0] = np.arange(30)[:, None] * 0.05   # right slides 1.5 m/s
    c = ds.foot_contacts(P, 30.0)
    assert c[:, 0].all() and not c[:, 1].any()


def test_sampler_ground_truth_is_consistent(cache):
    _, files = cache
    for kind in ("manikin", "fk"):
        s = ds.WindowSampler(files, window=16, kind=kind, augment=ds.Augment.off(), seed=0)
        b = s.sample(6)
        assert b["x"].shape == (6, 16, features.input_dim(body=True))
        assert b["y"].shape == (6, 16, features.output_dim(kind))
        bt = losses.to_torch(b)
        _, terms, _ = losses.compute_loss(bt["y"], bt, kind)
        assert terms["fk"] < 1e-5 and terms.get("mid", 0.0) < 1e-4 and terms.get("swivel", 0.0) < 1e-4
        m = losses.reduce_metrics([losses.metrics(bt["y"], bt, kind)])
        assert m["mpjpe_cm"] < 0.05, m          # ground truth through the pipeline = ground truth
    # augmented batches (speed, scale, noise, six trackers) stay finite and sized
    s = ds.WindowSampler(files, window=16, devices=("head", "left_hand", "right_hand", "pelvis", "left_foot",
                                                    "right_foot"), seed=1)
    b = s.sample(5)
    assert b["x"].shape == (5, 16, 72 + len(features.BODY_FEATURES)) and all(np.isfinite(v).all() for v in b.values())


def test_model_size_and_loss_decreases(cache):
    _, files = cache
    cfg = ModelConfig(window=16, d_model=32, heads=2, layers=1, head_hidden=32, dropout=0.0)
    assert count_parameters(PoseNet(ModelConfig())) < 2_000_000
    torch.manual_seed(0)
    model = PoseNet(cfg)
    batch = losses.to_torch(ds.WindowSampler(files, window=16, seed=0).sample(8))
    opt = torch.optim.Adam(model.parameters(), 3e-3)
    first = None
    for _ in range(30):
        total, _, _ = losses.compute_loss(model(batch["x"]), batch)
        opt.zero_grad()
        total.backward()
        opt.step()
        first = total.item() if first is None else first
    assert total.item() < 0.7 * first


# --------------------------------------------------------------------------
# train, resume, export
def test_train_resume_and_export(cache, bvh_dir, tmp_path):
    from blender_manikin.training import train, export
    root, _ = cache
    common = ["--bvh", bvh_dir, "--cache-dir", root, "--window", "16", "--steps", "6"] + TINY
    straight = train.main(common + ["--out", str(tmp_path / "a"), "--data-workers", "0"])
    assert straight["step"] == 6
    part = train.main(common + ["--out", str(tmp_path / "b"), "--stop-at", "3"])
    assert part["step"] == 3
    resumed = train.main(common + ["--out", str(tmp_path / "b"), "--resume"])   # batches made ahead in a worker
    assert resumed["step"] == 6
    a = torch.load(tmp_path / "a" / "checkpoint.pt", weights_only=False)
    b = torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=False)
    for k in a["model"]:
        assert torch.allclose(a["model"][k], b["model"][k], atol=1e-6), k
    assert b["step"] == 6 and "optimizer" in b and b["config"]["d_model"] == 32
    with pytest.raises(SystemExit):               # no silent overwrite of a run
        train.main(common + ["--out", str(tmp_path / "b")])

    out = tmp_path / "m.onnx"
    contract, diff = export.export(str(tmp_path / "b" / "checkpoint.pt"), str(out), quiet=True)
    assert diff <= 1e-4 and os.path.getsize(out) < 10 * 1024 * 1024
    c = export.read_contract(str(out))
    assert c == json.loads(json.dumps(contract))
    assert c["kind"] == "manikin" and c["window"] == 16 and c["fps"] == 30.0
    assert [tuple(x) for x in c["output_blocks"]] == list(features.OUTPUT_BLOCKS["manikin"])
    assert c["joint_names"] == list(sk.JOINT_NAMES) and c["input_devices"] == list(features.INPUT_DEVICES)
    assert c["normalisation"]["vel_scale"] == features.VEL_SCALE
    assert c["training_data"]["clips"] == 7 and c["training"]["steps"] == 6
    assert c["training_data"]["sampling"]["balance"] == 0.0       # every frame alike unless --balance
    assert c["licence"] == "unknown: state it in the sources file" and "mpjpe_cm" in c["validation"]
    assert [x["name"] for x in c["training_data"]["sources"]] == [os.path.basename(bvh_dir)]
    # the add-on's reader accepts it, and onnxruntime equals torch on a real batch
    from blender_manikin.core.model_runner import ModelRunner
    runner = ModelRunner(str(out), threads=1)
    assert runner.contract.kind == "manikin" and runner.num_parameters == c["num_parameters"]
    model = PoseNet(ModelConfig.from_dict(b["config"]))
    model.load_state_dict(b["model"])
    model.eval()
    x = ds.WindowSampler(ds.build_cache(bvh_dir, root, verbose=False), window=16, seed=3).sample(3)["x"]
    with torch.no_grad():
        ref = model(torch.from_numpy(x)).numpy()
    assert np.abs(runner.predict(x) - ref).max() < 1e-4


def test_resume_with_new_loss_weights(cache, bvh_dir, tmp_path):
    """Stage 2 of the shipped recipe: resume a run to a longer plan with --lam mid=1."""
    from blender_manikin.training import train
    root, _ = cache
    common = ["--bvh", bvh_dir, "--cache-dir", root, "--window", "16"] + TINY + ["--out", str(tmp_path / "r")]
    train.main(common + ["--steps", "3", "--balance", "0.5"])
    res = train.main(common + ["--steps", "5", "--resume", "--lam", "mid=1.0"])
    assert res["step"] == 5
    ck = torch.load(tmp_path / "r" / "checkpoint.pt", weights_only=False)
    assert ck["args"]["lam"] == ["mid=1.0"] and ck["step"] == 5
    # the class balance of the sampler survives the resume, and the run records each class's share
    assert ck["args"]["balance"] == 0.5 and ck["data"]["sampling"]["balance"] == 0.5
    shares = ck["data"]["sampling"]["group_shares"]
    assert set(shares) == {"dataset-t_walk", "cmu_07"} and abs(sum(shares.values()) - 1) < 1e-3
    with pytest.raises(SystemExit, match="--balance 2.0: expected a number from 0 to 1"):
        train.main(common[:-1] + [str(tmp_path / "bad"), "--steps", "1", "--balance", "2"])
    assert train.parse_lam(["mid=1", "foot=0.5"]) == {"mid": 1.0, "foot": 0.5}
    for bad in (["knee=1"], ["mid"], ["mid=x"]):
        with pytest.raises(SystemExit, match="--lam"):
            train.parse_lam(bad)


def test_fk_kind_six_trackers_causal_export(cache, bvh_dir, tmp_path):
    from blender_manikin.training import train, export
    from blender_manikin.core.model_runner import ModelRunner
    root, _ = cache
    r = train.main(["--bvh", bvh_dir, "--cache-dir", root, "--window", "12", "--steps", "2", "--kind", "fk",
                    "--six-trackers", "--causal", "--out", str(tmp_path / "fk")] + TINY)
    assert r["step"] == 2 and np.isfinite(r["val"]["mpjpe_cm"])
    out = tmp_path / "fk.onnx"
    contract, diff = export.export(r["checkpoint"], str(out), quiet=True)
    assert diff <= 1e-4 and contract["kind"] == "fk" and contract["causal"] is True
    F = 72 + len(features.BODY_FEATURES)
    assert len(contract["input_devices"]) == 6 and contract["input_shape"] == ["batch", 12, F]
    assert contract["body_features"] == list(features.BODY_FEATURES)
    assert contract["output_shape"][-1] == features.output_dim("fk")
    assert ModelRunner(str(out), threads=1).contract.kind == "fk"
    # causal: a frame's output does not depend on later frames
    ck = torch.load(r["checkpoint"], weights_only=False)
    model = PoseNet(ModelConfig.from_dict(ck["config"]))
    model.load_state_dict(ck["model"])
    model.eval()
    x = torch.randn(1, 12, F)
    x2 = x.clone()
    x2[:, 8:] += 1.0
    with torch.no_grad():
        assert torch.allclose(model(x)[:, :8], model(x2)[:, :8], atol=1e-6)
        assert not torch.allclose(model(x)[:, 8:], model(x2)[:, 8:])


def test_train_cli_selects_the_dual_attention_backbone(cache, bvh_dir, tmp_path):
    from blender_manikin.training import train, export
    from blender_manikin.training.model_dap import DualAttentionPoser
    from blender_manikin.training.backbones import build_model
    root, _ = cache
    r = train.main(["--bvh", bvh_dir, "--cache-dir", root, "--window", "12", "--steps", "2", "--arch", "dap",
                    "--out", str(tmp_path / "dap")] + TINY)
    ck = torch.load(r["checkpoint"], weights_only=False)
    assert ck["config"]["arch"] == "dap"
    assert isinstance(build_model(ModelConfig.from_dict(ck["config"])), DualAttentionPoser)
    contract, diff = export.export(r["checkpoint"], str(tmp_path / "dap.onnx"), quiet=True)
    assert diff <= 1e-4 and contract["architecture"]["arch"] == "dap"
    # its exported weights read back exactly for fine-tuning (--init): the graph's order of the
    # linear layers is not the order the model defines them in
    from blender_manikin.training.init_weights import load_initial_weights
    cfg, state = load_initial_weights(str(tmp_path / "dap.onnx"))
    assert cfg.arch == "dap"
    for k, v in ck["model"].items():
        assert torch.allclose(state[k], v, atol=1e-7), k


@pytest.mark.parametrize("flags, said", [
    (["--arch", "dap"], r"--arch dap: --init \S+ is a posenet model \(fine-tuning keeps its backbone"),
    (["--causal"], r"--causal: --init \S+ is not a causal model"),
    (["--six-trackers"], r"--six-trackers: --init \S+ takes head, left_hand, right_hand$"),
])
def test_init_refuses_a_backbone_or_inputs_other_than_its_own(tmp_path, flags, said):
    """Fine-tuning keeps the weights' architecture: ``--init manikin_s.onnx --arch dap`` (a user
    wanting a Dual Attention Poser from the shipped Transformer), ``--causal`` or ``--six-trackers``
    were dropped without a word and trained the Transformer, non-causal, on head and hands."""
    from blender_manikin.training import train
    from blender_manikin.core.model_choice import shipped_model_path
    with pytest.raises(SystemExit, match=said):
        train.main(["--bvh", str(tmp_path / "never_read"), "--out", str(tmp_path / "run"),
                    "--init", shipped_model_path("head_hands"), "--quiet"] + flags)
    assert not os.path.exists(tmp_path / "run" / "checkpoint.pt")


@pytest.fixture(scope="module")
def asf_dir(tmp_path_factory):
    """An ASF/AMC source (CMU layout): one performer, two takes of swaying and bending."""
    import sys
    sys.path.insert(0, os.path.dirname(__file__))
    from test_asf_amc import STAND_Y, _cmu_amc_text, _cmu_asf_text
    d = tmp_path_factory.mktemp("asf")
    (d / "asf").mkdir()
    (d / "amc").mkdir()
    (d / "asf" / "07.asf").write_text(_cmu_asf_text())
    for take in (1, 2):
        frames = []
        for k in range(60):
            a = 25 * np.sin(2 * np.pi * (k / 60) * take)
            frames.append({"root": (0.1 * k, STAND_Y, 0, 0, 3 * a, 0), "lfemur": (-abs(a), 0, 0),
                           "ltibia": (abs(a),), "lhumerus": (a, 0, 0), "rradius": (abs(a),)})
        (d / "amc" / f"07_{take:02d}.amc").write_text(_cmu_amc_text(frames))
    return str(d)


def test_select_on_keeps_the_best_checkpoint_on_another_source(cache, bvh_dir, asf_dir, tmp_path):
    """--select-on: an ASF/AMC source (cached like BVH) is evaluated at every checkpoint and best.pt
    is the checkpoint that did best on it."""
    from blender_manikin.training import train
    root, _ = cache
    files = ds.build_cache(asf_dir, root, workers=1, verbose=False)
    index, _ = ds.load_index(files)
    assert len(files) == 2 and index["format"] == "asf_amc" and index["frames"] > 0
    out = tmp_path / "sel"
    r = train.main(["--bvh", bvh_dir, "--cache-dir", root, "--window", "12", "--steps", "6", "--ckpt-steps", "2",
                    "--select-on", asf_dir, "--out", str(out)] + TINY)
    assert r["step"] == 6
    ck = torch.load(out / "checkpoint.pt", weights_only=False)
    hist = [h for h in ck["history"] if "select_mpjpe_cm" in h]
    assert [h["step"] for h in hist] == [2, 4, 6]
    best = torch.load(out / "best.pt", weights_only=False)
    assert best["step"] == min(hist, key=lambda h: h["select_mpjpe_cm"])["step"]


def test_resume_keeps_the_select_on_source_and_the_validation(cache, bvh_dir, asf_dir, tmp_path):
    """An interrupted run chosen on --select-on, resumed as the README says (``--out DIR
    --resume``): the rest of the run is still evaluated on that source, on the same windows and
    at the same checkpoints, and best.pt stays the best of them all (before, a plain --resume
    dropped --select-on, --val-windows and --ckpt-steps: best.pt stayed an early checkpoint)."""
    from blender_manikin.training import train
    root, _ = cache
    out = tmp_path / "sel"
    first = ["--bvh", bvh_dir, "--cache-dir", root, "--window", "12", "--steps", "8", "--ckpt-steps", "2",
             "--select-on", asf_dir, "--out", str(out)] + TINY
    straight = tmp_path / "straight"
    train.main(first[:-len(TINY) - 2] + ["--out", str(straight)] + TINY)
    train.main(first + ["--stop-at", "4"])
    train.main(["--out", str(out), "--resume", "--quiet", "--threads", "1"])
    ck = torch.load(out / "checkpoint.pt", weights_only=False)
    assert ck["args"]["select_on"] == asf_dir and ck["args"]["val_windows"] == 16 and ck["step"] == 8
    ref = torch.load(straight / "checkpoint.pt", weights_only=False)
    hist = [(h["step"], h["select_mpjpe_cm"]) for h in ck["history"] if "select_mpjpe_cm" in h]
    assert hist == [(h["step"], h["select_mpjpe_cm"]) for h in ref["history"] if "select_mpjpe_cm" in h]
    assert [s for s, _ in hist] == [2, 4, 6, 8]
    best = torch.load(out / "best.pt", weights_only=False)
    assert best["step"] == min(hist, key=lambda h: h[1])[0]


def test_sources_file_with_options_and_licences(cache, bvh_dir, asf_dir, tmp_path):
    """--sources: several sources, each with its reading options and licence; the model's licence is
    the most restrictive; a bad file is named with the entry at fault."""
    from blender_manikin.training import train, export
    root, _ = cache
    spec = tmp_path / "sources.json"
    spec.write_text(json.dumps([
        {"path": bvh_dir, "name": "synthetic BVH", "licence": "CC BY 4.0"},
        {"path": asf_dir, "name": "synthetic ASF", "joint_map": "cmu_asf", "fps": 60.0,
         "licence": "CC BY-NC 4.0"}]))
    r = train.main(["--sources", str(spec), "--cache-dir", root, "--window", "12", "--steps", "2",
                    "--out", str(tmp_path / "s")] + TINY)
    contract, _ = export.export(r["checkpoint"], str(tmp_path / "s.onnx"), quiet=True)
    srcs = contract["training_data"]["sources"]
    assert [x["name"] for x in srcs] == ["synthetic BVH", "synthetic ASF"]
    assert srcs[1]["format"] == "asf_amc" and srcs[1]["options"] == {"joint_map": "cmu_asf", "fps": 60.0}
    assert srcs[1]["frames"] == 2 * 30                 # 60 AMC frames stated as 60 fps -> 30 at 30 fps
    assert contract["licence"] == "CC BY-NC 4.0" and contract["training_data"]["clips"] == 9
    assert ds.combined_licence(["CC BY 4.0", "CC BY-SA 3.0", "CC BY-NC-ND 4.0", "CC BY-NC 4.0"]) == "CC BY-NC-ND 4.0"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps([{"path": bvh_dir, "licence": "x", "unit": "cm"}]))
    with pytest.raises(SystemExit, match="bad.json line 1: source 1: unknown field"):
        train.main(["--sources", str(bad), "--cache-dir", root, "--steps", "1", "--out", str(tmp_path / "b")] + TINY)


def test_combined_licence_never_takes_unrecognised_terms_as_permissive():
    """The weights' licence is the most restrictive source's: a non-commercial licence spelt
    without the hyphen, or terms the code does not know, must win over CMU's "free for all uses",
    whichever order the sources file lists them in."""
    cmu = "CMU Graphics Lab: free for all uses"
    for other in ("Studio licence: non commercial research use only", "CC BY NC 4.0",
                  "research use only, no redistribution"):
        assert ds.combined_licence([cmu, other]) == other
        assert ds.combined_licence([other, cmu]) == other
    assert ds.combined_licence([cmu, "CC BY 4.0"]) == cmu
    assert ds.combined_licence(["CC0 1.0", "CC BY-SA 3.0"]) == "CC BY-SA 3.0"
    assert ds.combined_licence(["Bandai Namco Research Inc.: CC BY 4.0", cmu]) != "unknown"
    assert ds.licence_rank("Copyright Bandai Namco Research Inc.; CC BY-NC-ND 4.0") == 4


def test_sources_file_fps_of_a_bvh_source(bvh_dir, tmp_path):
    """A BVH source with "fps" in the sources file builds (it set a read-only property, so every
    take was skipped: "no usable BVH clips"); the stated rate replaces the files' Frame Time."""
    src = ds.MotionSource(path=bvh_dir, fps=60.0)
    files = ds.build_cache(src, str(tmp_path), workers=1, verbose=False)
    index, _ = ds.load_index(files)
    assert not index["skipped"] and len(files) == 7
    # six 90-frame takes read as 60 fps -> 45 frames at 30 fps; the 240-frame take -> 120
    assert index["frames"] == 6 * 45 + 120


@pytest.mark.parametrize("field, value, problem", [
    ("joint_map", "cmu-asf", "unknown joint_map 'cmu-asf' (expected one of 100style, bandai, cmu, cmu_asf, "
     "lafan1, mixamo, neuron, rokoko or a joint-map .json file)"),
    ("unit_scale", "centimetres", "unit_scale must be metres per unit"),
    ("unit_scale", -0.01, "unit_scale must be metres per unit"),
    ("up", "Y-up", "up must be an axis"),
    ("forward", "y", "must be different axes"),
    ("fps", 0, "fps must be a positive number, got 0"),
    ("licence", ["CC BY 4.0"], "licence must be a non-empty string"),
])
def test_sources_file_bad_values_name_file_line_and_problem(tmp_path, field, value, problem):
    """A bad value in the sources file is reported when the file is read, with the file, the
    line of the entry and the problem; before, it passed, and every take of the source was then
    skipped ("no usable BVH clips ... KeyError: 'centimetres'"), fps 0 was read as 120, and a
    licence that is not a string failed only after every cache was built."""
    spec = tmp_path / "sources.json"
    entry = {"path": "cmu", "name": "CMU", "licence": "CMU: free for all uses", "up": "y", field: value}
    spec.write_text('[\n  {"path": "bandai.tar.xz"},\n\n  ' + json.dumps(entry) + "\n]\n")
    with pytest.raises(ValueError) as exc:
        ds.load_sources(str(spec))
    assert str(exc.value).startswith(f"{spec} line 4: source 2: ") and problem in str(exc.value)
    spec.write_text(json.dumps([{"path": "cmu", "joint_map": "cmu_asf", "unit_scale": "auto", "up": "-Y",
                                 "forward": "z", "fps": 120, "licence": "CMU"}]))
    assert ds.load_sources(str(spec))[0].fps == 120


def test_aug_overrides_and_their_checks():
    from blender_manikin.training import train
    aug = train.parse_aug(["arm_mix=0", "stature=1.5,1.9", "dropout=0.25"])
    assert aug.arm_mix == 0.0 and aug.stature == (1.5, 1.9) and aug.dropout == 0.25
    assert train.parse_aug(["stature=none"]).stature is None
    for bad, msg in (("nope=1", "FIELD one of"), ("arm_mix=x", "not a number"), ("stature=1.5", "two numbers"),
                     ("arm_mix=1,2", "one number"), ("stoop_knees=0.9", "stoop_knees 0.9: must be between 0"),
                     ("stoop_knees=-0.1", "must be between 0"), ("stoop_bend=90,40", "stoop_bend 90,40: must be"),
                     ("stoop_look=2", "stoop_look 2.0: must be")):
        with pytest.raises(SystemExit, match=msg):
            train.parse_aug([bad])
    aug = train.parse_aug(["stoop_knees=0.45", "stoop_bend=25,125", "stoop_look=0.6"])
    assert aug.stoop_knees == 0.45 and aug.stoop_bend == (25.0, 125.0) and aug.stoop_look == 0.6


def test_init_fine_tunes_from_a_checkpoint_or_an_exported_model(cache, bvh_dir, tmp_path):
    """--init starts a new run from trained weights: a checkpoint, or an .onnx read back exactly
    (its contract gives the architecture); the run's first weights are those weights."""
    from blender_manikin.training import train, export
    from blender_manikin.training.init_weights import load_initial_weights
    root, _ = cache
    common = ["--bvh", bvh_dir, "--cache-dir", root, "--window", "16"] + TINY
    first = train.main(common + ["--steps", "3", "--out", str(tmp_path / "a")])
    onnx_path = tmp_path / "a.onnx"
    export.export(first["checkpoint"], str(onnx_path), quiet=True)
    ck = torch.load(first["checkpoint"], weights_only=False)
    for src in (first["checkpoint"], str(onnx_path)):
        cfg, state = load_initial_weights(src)
        assert cfg.d_model == 32 and cfg.layers == 1 and tuple(cfg.devices) == features.INPUT_DEVICES
        for k, v in ck["model"].items():
            assert torch.allclose(state[k], v, atol=1e-7), (src, k)
    # a fine-tuning run: zero steps keeps the weights, a few steps change them; the contract says so
    same = train.main(common + ["--steps", "0", "--init", str(onnx_path), "--out", str(tmp_path / "b")])
    kept = torch.load(same["checkpoint"], weights_only=False)
    for k, v in ck["model"].items():
        assert torch.allclose(kept["model"][k], v, atol=1e-7), k
    tuned = train.main(common + ["--steps", "2", "--init", str(onnx_path), "--out", str(tmp_path / "c"),
                                 "--aug", "lying=0.5", "--dropout", "0.2"])
    t = torch.load(tuned["checkpoint"], weights_only=False)
    # dropout is a training setting the exported model does not carry: --dropout sets it for --init runs
    assert kept["config"]["dropout"] == 0.05 and t["config"]["dropout"] == 0.2
    assert any(not torch.allclose(t["model"][k], v) for k, v in ck["model"].items())
    c, _ = export.export(tuned["checkpoint"], str(tmp_path / "c.onnx"), quiet=True)
    assert c["training"]["init"] == "a.onnx" and c["training_data"]["augmentation"]["lying"] == 0.5
    # wrong files are refused with the reason, before any training
    with pytest.raises(SystemExit, match="no such file"):
        train.main(common + ["--steps", "1", "--init", str(tmp_path / "none.onnx"), "--out", str(tmp_path / "d")])
    with pytest.raises(SystemExit, match="takes head, left_hand, right_hand"):
        train.main(common + ["--steps", "1", "--init", str(onnx_path), "--devices", "head,left_hand,right_hand,pelvis",
                             "--out", str(tmp_path / "e")])
    bad = tmp_path / "bad.pt"
    torch.save({"weights": 1}, bad)
    with pytest.raises(SystemExit, match="not a training checkpoint"):
        train.main(common + ["--steps", "1", "--init", str(bad), "--out", str(tmp_path / "f")])


def test_init_with_another_window_lines_up_the_centre_frame(cache, bvh_dir, tmp_path):
    """--init PATH --window W fine-tunes with a wider (or narrower) window: the positional
    embedding keeps its centre frame where the canonical frame is taken, the frames it did not
    cover repeat its ends, every other weight is the model's own; the contract records the new
    window.  The Dual Attention Poser, whose frame mixing is sized by the window, is refused."""
    from blender_manikin.training import train, export
    from blender_manikin.training.init_weights import load_initial_weights, widen_window
    root, _ = cache
    common = ["--bvh", bvh_dir, "--cache-dir", root] + TINY
    first = train.main(common + ["--window", "16", "--steps", "2", "--out", str(tmp_path / "a")])
    onnx_path = tmp_path / "a.onnx"
    export.export(first["checkpoint"], str(onnx_path), quiet=True)
    cfg, state = load_initial_weights(str(onnx_path))
    wide = train.main(common + ["--window", "24", "--steps", "0", "--init", str(onnx_path),
                                "--out", str(tmp_path / "b")])
    w = torch.load(wide["checkpoint"], weights_only=False)
    assert w["config"]["window"] == 24
    pos, old = w["model"]["pos"][0], state["pos"][0]                  # (24, d), (16, d)
    assert torch.equal(pos[4:20], old)                                # old centre 8 -> new centre 12
    assert torch.equal(pos[:4], old[:1].expand(4, -1)) and torch.equal(pos[20:], old[-1:].expand(4, -1))
    for k, v in state.items():
        if k != "pos":
            assert torch.equal(w["model"][k], v), k
    c, _ = export.export(wide["checkpoint"], str(tmp_path / "b.onnx"), quiet=True)
    assert c["architecture"]["window"] == 24 and c["centre_frame"] == 12
    narrow_cfg, narrow = widen_window(cfg, state, 10)                  # the centred slice
    assert narrow_cfg.window == 10 and torch.equal(narrow["pos"][0], old[3:13])
    with pytest.raises(ValueError, match="only posenet weights"):
        widen_window(dataclasses.replace(cfg, arch="dap"), state, 24)


def test_weight_average_formula_and_swap():
    """WeightAverage: avg = d avg + (1 - d) w with d = min(decay, (1 + n) / (10 + n)); applied() swaps
    the average in and the raw weights back."""
    from blender_manikin.training.weight_average import WeightAverage
    lin = torch.nn.Linear(2, 1)
    with torch.no_grad():
        lin.weight.fill_(0.0)
        lin.bias.fill_(0.0)
    avg = WeightAverage(lin, 0.5)
    expect = 0.0
    for n, w in enumerate((1.0, 2.0, 4.0)):
        with torch.no_grad():
            lin.weight.fill_(w)
        d = min(0.5, (1 + n) / (10 + n))
        assert avg.rate() == pytest.approx(d)
        avg.update(lin)
        expect = d * expect + (1 - d) * w
    assert torch.allclose(avg.weights["weight"], torch.full((1, 2), expect))
    with avg.applied(lin):
        assert torch.allclose(lin.weight, torch.full((1, 2), expect))
    assert torch.all(lin.weight == 4.0)
    with pytest.raises(ValueError, match="decay"):
        WeightAverage(lin, 1.0)


def test_ema_run_resumes_exactly_and_exports_the_average(cache, bvh_dir, asf_dir, tmp_path):
    """--ema: the average survives --resume bit for bit, best.pt is chosen on the average's
    --select-on error (the raw weights' is logged beside it), and export writes the average."""
    from blender_manikin.training import train, export
    from blender_manikin.core.model_runner import ModelRunner
    root, _ = cache
    common = ["--bvh", bvh_dir, "--cache-dir", root, "--window", "12", "--steps", "6", "--ema", "0.9",
              "--ckpt-steps", "2", "--select-on", asf_dir] + TINY
    train.main(common + ["--out", str(tmp_path / "a")])
    train.main(common + ["--out", str(tmp_path / "b"), "--stop-at", "3"])
    train.main(common[:-len(TINY)] + ["--out", str(tmp_path / "b"), "--resume"] + TINY)
    a = torch.load(tmp_path / "a" / "checkpoint.pt", weights_only=False)
    b = torch.load(tmp_path / "b" / "checkpoint.pt", weights_only=False)
    assert a["ema"]["updates"] == b["ema"]["updates"] == 6 and b["args"]["ema"] == 0.9
    for k, v in a["ema"]["weights"].items():
        assert torch.allclose(v, b["ema"]["weights"][k], atol=1e-6), k
    assert any(not torch.allclose(v, a["model"][k]) for k, v in a["ema"]["weights"].items())
    hist = [h for h in a["history"] if "select_mpjpe_cm" in h]
    assert [h["step"] for h in hist] == [2, 4, 6] and all("raw_select_mpjpe_cm" in h for h in hist)
    assert any(h["raw_select_mpjpe_cm"] != h["select_mpjpe_cm"] for h in hist)
    best = torch.load(tmp_path / "a" / "best.pt", weights_only=False)
    assert best["step"] == min(hist, key=lambda h: h["select_mpjpe_cm"])["step"]

    out = tmp_path / "ema.onnx"
    contract, _ = export.export(str(tmp_path / "a" / "checkpoint.pt"), str(out), quiet=True)
    assert contract["training"]["weight_average"] == {"decay": 0.9, "updates": 6}
    x = ds.WindowSampler(ds.build_cache(bvh_dir, root, verbose=False), window=12, seed=3).sample(2)["x"]
    got = ModelRunner(str(out), threads=1).predict(x)
    outs = {}
    for name in ("ema", "model"):
        model = PoseNet(ModelConfig.from_dict(a["config"]))
        model.load_state_dict(a["ema"]["weights"] if name == "ema" else a["model"])
        model.eval()
        with torch.no_grad():
            outs[name] = model(torch.from_numpy(x)).numpy()
    assert np.abs(got - outs["ema"]).max() < 1e-4 < np.abs(got - outs["model"]).max()
