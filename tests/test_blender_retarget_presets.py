"""Retargeting in Blender onto characters named and standing as the engines and rigging tools
give them (tests/blender_util.py ``RIG_STYLES``): the Unreal Mannequin (UE4 and UE5, twist bones,
IK bones, fingers, centimetres, facing +Y), a VRoid / VRM character, an Auto-Rig Pro export (each
limb segment split into a twist and a stretch bone), a
Character Creator 3/4 character (centimetres, +Y up; a pelvis bone between the hips bone and the
thighs, twist bones) and a Daz Genesis 8 figure (decimetres; Bend/Twist chains, four spine bones).

Every character has an A-pose rest, randomly rolled bones and proportions of its own: within the
torso, the arms and the legs every segment has one ratio to the performer's (``humanoid_joints``),
so where the retarget puts the hands, feet and head is known from the performer's joints alone:

* the root (pelvis) bone: its rest head plus ``k F (pelvis(t) - pelvis_rest)``, ``k`` the leg ratio
  (target leg length over the performer's: the default ``"scaled"`` root motion of
  ``core/retarget.py``), ``F`` the turn from the performer's facing (-Y) to the character's;
* the head and hands: the root plus each segment of the performer (in ``F``) times its region's
  ratio -- the retarget transfers segment directions, the character keeps its own lengths;
* the feet: the character's rest ankles plus ``k F (ankle(t) - ankle_rest)``: the legs are solved
  onto the performer's feet scaled like the root motion, so planted feet stay planted;
* with "keep hands and feet on the trackers" (``keep_ends``, scaled root motion) the hands are
  re-solved onto the root plus ``k F (wrist(t) - pelvis(t))``, the feet as above.

Planted feet: a walk whose feet are planted (``planted_feet_result``, ``contacts``) onto the same
characters, and onto one whose thighs and shanks have other ratios than the performer's (a transfer
of directions alone would slide its feet ~3.5 cm/s: the retarget solves the legs onto the scaled
feet in every mode, so they stay planted).
"""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import keying, retarget_apply, writer  # noqa: E402
from blender_manikin.core import bone_maps  # noqa: E402
from blender_manikin.core import rotations as rot  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402

from blender_util import (RIG_STYLES, build_armature, humanoid_bones, humanoid_joints,  # noqa: E402
                          live_auto_rig_pro_character, planted_feet_result, style_twist, styled_character,
                          synthetic_result)

T = 60
FPS = 24.0                       # the factory scene's rate: one source frame per scene frame
SRC_STATURE = 1.8
FRAMES = np.arange(1, T + 1)
STYLES = tuple(RIG_STYLES)
EY = np.array([0.0, 1.0, 0.0])
#: the joint a twisted segment ends at
NEXT_JOINT = {"shoulder": "elbow", "elbow": "wrist", "hip": "knee", "knee": "ankle"}
ENDS = {"left_wrist": "arm", "right_wrist": "arm", "left_ankle": "leg", "right_ankle": "leg", "head": "torso"}
LIMB_OF_END = {"left_wrist": ("left_shoulder", "left_elbow"), "right_wrist": ("right_shoulder", "right_elbow"),
               "left_ankle": ("left_hip", "left_knee"), "right_ankle": ("right_hip", "right_knee")}


def _write_source(res):
    return writer.write_result(res, writer.WriteOptions(frame_start=1)).armature


def _rest(obj):
    """Armature-space rest matrices ``{bone: (4, 4)}``."""
    return {b.name: np.array(b.matrix_local, dtype=np.float64) for b in obj.data.bones}


def _evaluate(obj, frames=FRAMES):
    """Posed bones after ``frame_set``: ``{bone: (F, 4, 4)}`` armature-space matrices
    (``pose_bone.matrix``) and ``{bone: (F, 4, 4)}`` ``matrix_basis``."""
    sc = bpy.context.scene
    names = [b.name for b in obj.pose.bones]
    M = np.empty((len(frames), len(names), 4, 4))
    basis = np.empty_like(M)
    for t, f in enumerate(frames):
        sc.frame_set(int(f))
        for k, pb in enumerate(obj.pose.bones):
            M[t, k] = np.array(pb.matrix, dtype=np.float64)
            basis[t, k] = np.array(pb.matrix_basis, dtype=np.float64)
    return {n: M[:, k] for k, n in enumerate(names)}, {n: basis[:, k] for k, n in enumerate(names)}


def _world_heads(obj, M, name):
    W = np.array(obj.matrix_world, dtype=np.float64)
    return M[name][:, :3, 3] @ W[:3, :3].T + W[:3, 3]


def _predicted(spec, obj, pos, body, root_bone):
    """Where the character's joints go under the default scaled retarget (module docstring):
    ``{joint: (T, 3)}`` world metres for the pelvis and the end joints, ``k``, and ``{ankle: (3,)}``
    the feet's targets less the root plus ``k F (ankle(t) - pelvis(t))``."""
    c = spec["stature"] / SRC_STATURE
    ratio = {"torso": c * spec["torso"], "arm": c * spec["arm"], "leg": c * spec["leg"]}
    k = ratio["leg"]
    F = spec["F"]
    W = np.array(obj.matrix_world, dtype=np.float64)
    root_rest = W[:3, :3] @ np.array(obj.data.bones[root_bone].head_local) + W[:3, 3]
    P = pos - pos[:, :1]                                   # performer's joints from its pelvis
    J = sk.J
    out = {"pelvis": root_rest + k * (pos[:, 0] - body.root_rest) @ F.T}
    out["head"] = out["pelvis"] + ratio["torso"] * P[:, J["head"]] @ F.T
    C, S = spec["joints"], body.rest_positions()            # the character's and the performer's rest
    feet = {f"{side}_ankle": (C[J[f"{side}_ankle"]] - C[0] - k * (S[J[f"{side}_ankle"]] - S[0])) @ F.T
            for side in ("left", "right")}
    for side in ("left", "right"):
        sh = J[f"{side}_shoulder"]
        out[f"{side}_wrist"] = out["pelvis"] + (ratio["torso"] * P[:, sh] + ratio["arm"] * (
            P[:, J[f"{side}_wrist"]] - P[:, sh])) @ F.T
        # the legs are solved onto the performer's feet scaled like the root motion
        out[f"{side}_ankle"] = out["pelvis"] + k * P[:, J[f"{side}_ankle"]] @ F.T + feet[f"{side}_ankle"]
    return out, k, feet


def _guess_differences(guessed, preset):
    """Readable differences between two maps ('' when they are the same)."""
    lines = [f"{j}: guessed {guessed.bones.get(j)!r}, preset {preset.bones.get(j)!r}" for j in sk.JOINT_NAMES
             if guessed.bones.get(j) != preset.bones.get(j)]
    lines += [f"twist of {j}: guessed {guessed.twist.get(j)}, preset {preset.twist.get(j)}"
              for j in sk.JOINT_NAMES if list(guessed.twist.get(j, [])) != list(preset.twist.get(j, []))]
    return "; ".join(lines)


def _without_twist(bmap):
    return bone_maps.BoneMap(bmap.name + "_no_twist", dict(bmap.bones), {})


def _same_pose(A, B, units):
    """Largest rotation-entry and translation (metres) differences of ``(..., 4, 4)`` matrices in
    armature units."""
    return (float(np.abs(A[..., :3, :3] - B[..., :3, :3]).max()),
            float(np.abs(A[..., :3, 3] - B[..., :3, 3]).max()) / units)


def _twist_rel(M, rest, parent, child):
    """``(T, 3, 3)``: ``child``'s armature-space orientation relative to ``parent``'s, taken back by
    their rest relation (identity when the child is at rest under the parent)."""
    Bp, Bc = rest[parent][:3, :3], rest[child][:3, :3]
    Gp, Gc = M[parent][:, :3, :3], M[child][:, :3, :3]
    return np.swapaxes(Gp @ (Bp.T @ Bc), -1, -2) @ Gc


@pytest.mark.parametrize("style", STYLES)
def test_retarget_onto_an_engine_or_tool_rig(addon, style, tmp_path):
    """The preset chosen by name (and the same map from the guess): hands, feet and head where
    the proportion scaling puts them (< 1 cm), within 0.1 mm of their targets with keep_ends, no
    flips, twist bones with their share of the twist, every other bone untouched."""
    res = synthetic_result(T=T, fps=FPS, seed=4, stature=SRC_STATURE, with_targets=False)
    src = _write_source(res)
    char, spec = styled_character(style)
    names = [b.name for b in char.data.bones]
    # the preset as choosing it by name gives it: fitted to the character (its twist bones)
    preset = bone_maps.validate_bone_map(
        bone_maps.fit_twist(bone_maps.preset(style), retarget_apply.bone_list(char)), names)
    # every bone the style's table names is what the preset maps (the preset's names are real)
    assert {j: b for j, b in preset.bones.items()} == {
        j: (v if isinstance(v, str) else v[0]) for j, v in spec["names"].items()}
    assert preset.twist == style_twist(spec), preset.twist
    # the guess ("auto") finds the same map
    guessed, notes = retarget_apply.resolve_bone_map("auto", char)
    assert guessed.name == style and _guess_differences(guessed, preset) == "", _guess_differences(guessed, preset)

    pos, _ = res.fk()
    rest = _rest(char)
    for k, pb in enumerate(char.pose.bones):            # the animator's own rotation modes
        pb.rotation_mode = ('XYZ', 'QUATERNION', 'YZX')[k % 3]
    modes_before = {pb.name: pb.rotation_mode for pb in char.pose.bones}
    action, out, notes = retarget_apply.retarget_onto(src, char, style, None, "scaled", False)
    # a leg may fall short of its foot by millimetres where this take turns the pelvis far (checked below)
    assert [n for n in notes if "leg: out of the character's reach" not in n] == []
    M, basis = _evaluate(char)
    expect, k, feet = _predicted(spec, char, pos, res.body, preset.bones["pelvis"])
    assert abs(out.plan.leg_ratio - k) < 1e-6                     # bones are stored in float32
    errors = {}
    for joint in ("pelvis",) + tuple(ENDS):
        got = _world_heads(char, M, preset.bones[joint])
        err = np.linalg.norm(got - expect[joint], axis=-1)
        assert err.max() < 0.01, (joint, err.max())                  # the 1 cm
        if joint.endswith("ankle"):    # the legs' reach: where the scaled foot is out of it, the
            li = sk.LIMB_NAMES.index(("left" if joint.startswith("left") else "right") + "_leg")
            assert np.abs(err - out.reach_error[:, li]).max() < 1e-4, joint    # result says by how much
            err = err[out.reach_error[:, li] < 1e-6]
        errors[joint] = float(err.max())
    assert max(errors.values()) < 1e-4, errors                      # in fact float32 round-off

    # no bone turns more than 90° between frames (flips), none more than twice its source's
    # fastest joint does
    src_step = float(rot.geodesic_angle(res.fk()[1][1:], res.fk()[1][:-1]).max())
    step = {n: float(rot.geodesic_angle(m[1:, :3, :3], m[:-1, :3, :3]).max()) for n, m in M.items()}
    worst = max(step, key=step.get)
    assert step[worst] < np.pi / 2, (worst, step[worst])
    assert step[worst] < 2 * src_step, (worst, step[worst], src_step)

    # bones the map does not name keep their rest pose under their parent and carry no keys
    driven = set(preset.target_bones())
    untouched = [n for n in names if n not in driven]
    assert len(untouched) >= 8
    keyed_bones = {fc.data_path.split('"')[1] for fc in keying.action_fcurves(action, char)
                   if fc.data_path.startswith("pose.bones[")}
    assert keyed_bones == driven, sorted(keyed_bones ^ driven)
    u = spec["units"]
    for n in untouched:
        assert np.abs(basis[n] - np.eye(4)).max() < 1e-6, n
        par = char.data.bones[n].parent
        if par is None:
            dr, dt = _same_pose(M[n], rest[n], u)
        else:
            dr, dt = _same_pose(np.linalg.inv(M[par.name]) @ M[n], np.linalg.inv(rest[par.name]) @ rest[n], u)
        assert dr < 1e-5 and dt < 1e-5, (n, dr, dt)
    # the IK bones hang from the unmapped root: they stay where they were, in the world
    ik = [n for n in untouched if n.startswith("ik_")]
    for n in ik:
        dr, dt = _same_pose(M[n], rest[n], u)
        assert dr < 1e-6 and dt < 1e-6, (n, dr, dt)
    assert len(ik) == (7 if style.startswith("ue") else 0)

    # twist bones: the segment's twist ramps from none at its base to all at its tip; each bone
    # takes the middle of the stretch it spans (the mapped bone from the base to the first twist
    # bone, each twist bone to the next one or the tip), as measured from the character's rest
    # heads; checked against the same retarget without twist bones (a saved map)
    if preset.twist:
        plain = tmp_path / f"{style}_no_twist.json"
        bone_maps.save_bone_map(plain, _without_twist(preset))
        retarget_apply.retarget_onto(src, char, "file", str(plain), "scaled", False)
        M0, basis0 = _evaluate(char)
        # no longer keyed: back at rest in their own rotation mode, not at the first action's last
        # pose (Blender leaves channels without F-curves where they were)
        for b in (b for v in preset.twist.values() for b in v):
            assert np.abs(basis0[b] - np.eye(4)).max() < 1e-6, b
            assert char.pose.bones[b].rotation_mode == modes_before[b], b
        twisted = 0
        for joint, tw in preset.twist.items():
            main = preset.bones[joint]
            parent = char.data.bones[main].parent.name
            side, part = joint.split("_", 1)
            h0, h1 = rest[main][:3, 3], rest[preset.bones[f"{side}_{NEXT_JOINT[part]}"]][:3, 3]
            at = [0.0] + [float((rest[b][:3, 3] - h0) @ (h1 - h0) / ((h1 - h0) @ (h1 - h0))) for b in tw] + [1.0]
            shares = [0.5 * (a + b) for a, b in zip(at[:-1], at[1:])]
            if style == "cc4":                  # Twist01 at the segment's head, Twist02 half-way
                assert np.allclose(shares, [0.0, 0.25, 0.75], atol=1e-4), (joint, shares)
            tau = np.unwrap(rot.twist_angle(_twist_rel(M0, rest, parent, main), EY))
            twisted += np.ptp(tau) > 0.2
            G0, G1 = M0[main][:, :3, :3], M[main][:, :3, :3]
            # the bone still points where it did; it turned back about itself by what it does not keep
            assert np.abs(G1[:, :, 1] - G0[:, :, 1]).max() < 1e-5, (joint, "direction")
            share = rot.twist_angle(np.swapaxes(G0, -1, -2) @ G1, EY)
            assert np.abs(np.angle(np.exp(1j * (share + (1 - shares[0]) * tau)))).max() < 1e-4, joint
            for i, b in enumerate(tw):
                rel = _twist_rel(M, rest, main, b)
                expect_rel = rot.axis_angle_rotation(EY, (shares[i + 1] - shares[0]) * tau)
                assert np.abs(rel[:, :3, :3] - expect_rel).max() < 1e-4, (joint, b)
        assert twisted >= 4, "the take does not twist the limbs: the check above would prove nothing"
        # what hangs below the twisted segments does not move
        for j in ("left_wrist", "right_wrist", "left_ankle", "right_foot", "head"):
            dr, dt = _same_pose(M[preset.bones[j]], M0[preset.bones[j]], u)
            assert dr < 1e-5 and dt < 1e-5, (j, dr, dt)

    # keep hands and feet on the trackers: re-solved onto the scaled targets, within 0.1 mm
    _, out_k, notes_k = retarget_apply.retarget_onto(src, char, style, None, "scaled", True)
    Mk, _ = _evaluate(char)
    end_err, reached = {}, {}
    for j, (base, mid) in LIMB_OF_END.items():
        got = _world_heads(char, Mk, preset.bones[j])
        hb = _world_heads(char, Mk, preset.bones[base])
        hm = _world_heads(char, Mk, preset.bones[mid])
        l1 = np.linalg.norm(hm - hb, axis=-1)[0]
        l2 = np.linalg.norm(got - hm, axis=-1)[0]
        if j.endswith("wrist"):      # from the character's shoulder, by the ratio of arm lengths
            js, je = sk.J[j.replace("wrist", "shoulder")], sk.J[j.replace("wrist", "elbow")]
            arm = np.linalg.norm(pos[0, je] - pos[0, js]) + np.linalg.norm(pos[0, sk.J[j]] - pos[0, je])
            target = hb + (l1 + l2) / arm * (pos[:, sk.J[j]] - pos[:, js]) @ spec["F"].T
        else:
            target = expect["pelvis"] + k * (pos[:, sk.J[j]] - pos[:, 0]) @ spec["F"].T + feet.get(j, 0.0)
        # reachable, judged from the character's own limb (base head to target, its two lengths)
        ok = np.linalg.norm(target - hb, axis=-1) < l1 + l2 - 1e-3
        reached[j] = float(ok.mean())
        err = np.linalg.norm(got - target, axis=-1)
        end_err[j] = float(err[ok].max()) if ok.any() else float("nan")
        assert reached[j] >= 0.5, (j, reached[j])
        assert end_err[j] < 1e-4, (j, end_err[j])                  # 0.1 mm
        # where it is out of reach, the result says by how much and the notes tell the user
        li = {"left_wrist": 0, "right_wrist": 1, "left_ankle": 2, "right_ankle": 3}[j]
        assert np.abs(out_k.reach_error[:, li] - err).max() < 1e-4, j
        limb = sk.LIMB_NAMES[li].replace("_", " ")
        noted = any(n.startswith(limb) and "out of the character's reach" in n for n in notes_k)
        assert noted == bool((err > 0.005).any()), (j, notes_k)
    print(f"\n{style}: k={k:.4f} ends (no keep_ends) {errors}; keep_ends {end_err} reached {reached}; "
          f"max step {np.degrees(step[worst]):.1f} deg ({worst}), source {np.degrees(src_step):.1f} deg")


def _slides(obj, M, bone, contacts):
    """Horizontal steps (metres) of ``bone``'s head between consecutive frames both planted."""
    h = _world_heads(obj, M, bone)
    both = contacts[1:] & contacts[:-1]
    return np.linalg.norm(np.diff(h[:, :2], axis=0), axis=-1)[both]


@pytest.mark.parametrize("style", STYLES)
def test_planted_feet_stay_planted_on_the_character(addon, style):
    """A walk whose feet are planted (``result.contacts``): the character's foot and toe bones do
    not slide on those frames, with the default scaled root motion and with keep_ends.

    Thresholds: foot skate shows when a planted foot drifts more than a few millimetres over a
    step; 1 cm/s mean is under 1 cm over a whole stance (here ~0.9 s), 1 mm a frame is 2.4 cm/s
    at 24 fps, below a visible jitter.  The performer's own planted feet (the reference level) are
    still to float round-off; the legs are solved onto the planted feet (scaled with the root
    motion) in both modes, so the character's are too (a transfer of directions alone left
    2-6 mm/s here: the pelvis turning ±0.15 rad a hip offset scaled by the torso's ratio)."""
    res = planted_feet_result(T=T, fps=FPS, stature=SRC_STATURE)
    src = _write_source(res)
    char, spec = styled_character(style)
    preset = bone_maps.preset(style)
    Ms, _ = _evaluate(src)
    report = {}
    ref = {}
    for i, side in enumerate(("left", "right")):
        for j in ("ankle", "foot"):
            ref[f"{side}_{j}"] = _slides(src, Ms, f"{side}_{j}", res.contacts[:, i])
    ref_max = max(float(v.max()) for v in ref.values())
    assert ref_max < 1e-5, ref_max                          # the performer's feet are planted
    assert min(len(v) for v in ref.values()) >= 20          # and for long enough to tell
    for keep in (False, True):
        retarget_apply.retarget_onto(src, char, style, None, "scaled", keep)
        M, _ = _evaluate(char)
        for i, side in enumerate(("left", "right")):
            for j in ("ankle", "foot"):
                d = _slides(char, M, preset.bones[f"{side}_{j}"], res.contacts[:, i])
                mean_speed, step = float(d.mean() * FPS), float(d.max())
                report[(keep, f"{side}_{j}")] = (mean_speed, step)
                assert mean_speed < 0.01, (style, keep, side, j, mean_speed)        # < 1 cm/s
                assert step < 0.001, (style, keep, side, j, step)                   # < 1 mm a frame
                assert step < 1e-5, (style, keep, side, step)       # the legs are re-solved: still
    print(f"\n{style}: reference max step {ref_max:.2e} m; " + "; ".join(
        f"{'keep_ends' if kp else 'scaled'} {b}: {1000 * v[0]:.2f} mm/s mean, {1000 * v[1]:.3f} mm max"
        for (kp, b), v in report.items()))


def test_planted_feet_of_legs_of_other_proportions_stay_put(addon):
    """Thighs 12 % longer and shanks 12 % shorter than the performer's (same leg length): a
    transfer of the leg segments' directions would move the foot on as the knee bends (~3.5 cm/s
    measured before the legs were re-solved in every mode); with and without keep_ends the legs
    are solved onto the planted feet and they stay put."""
    res = planted_feet_result(T=T, fps=FPS, stature=SRC_STATURE)
    src = _write_source(res)
    bmap = bone_maps.preset("mixamo")
    P = humanoid_joints(1.7, 40.0, thigh_shank=(1.12, 0.88))
    char = build_armature("LongThighs", humanoid_bones(P, bmap.bones), seed=11)
    slides = {}
    for keep in (False, True):
        retarget_apply.retarget_onto(src, char, "mixamo", None, "scaled", keep)
        M, _ = _evaluate(char)
        for i, side in enumerate(("left", "right")):
            for j in ("ankle", "foot"):
                d = _slides(char, M, bmap.bones[f"{side}_{j}"], res.contacts[:, i])
                slides[(keep, f"{side}_{j}")] = (float(d.mean() * FPS), float(d.max()))
                assert d.max() < 1e-5, (keep, side, j, d.max())
    print("\nlong thighs: " + "; ".join(f"{'keep_ends' if kp else 'scaled'} {b}: {1000 * v[0]:.2f} mm/s mean, "
                                         f"{1000 * v[1]:.3f} mm max" for (kp, b), v in slides.items()))


def test_a_saved_and_reloaded_ue5_map_gives_the_same_keys(addon, tmp_path):
    """The UE5 map, guessed, saved as JSON and loaded again (twist lists in their base-to-tip
    order), keys the character exactly as the preset chosen by name does."""
    res = synthetic_result(T=T, fps=FPS, seed=5, stature=SRC_STATURE, with_targets=False)
    src = _write_source(res)
    char, _ = styled_character("ue5")
    guessed, _ = retarget_apply.resolve_bone_map("auto", char)
    path = tmp_path / "my_character.json"
    bone_maps.save_bone_map(path, guessed)
    back = bone_maps.load_bone_map(path)
    assert back.to_dict() == guessed.to_dict()
    assert back.twist["left_elbow"] == ["lowerarm_twist_02_l", "lowerarm_twist_01_l"]

    def keys(action):
        out = {}
        for fc in keying.action_fcurves(action, char):
            co = np.empty(2 * len(fc.keyframe_points), dtype=np.float32)
            fc.keyframe_points.foreach_get("co", co)
            out[(fc.data_path, fc.array_index)] = co
        return out
    a_preset, _, _ = retarget_apply.retarget_onto(src, char, "ue5", None, "scaled", True)
    M_preset, _ = _evaluate(char)
    a_file, _, _ = retarget_apply.retarget_onto(src, char, "file", str(path), "scaled", True)
    M_file, _ = _evaluate(char)
    assert a_file != a_preset
    k_preset, k_file = keys(a_preset), keys(a_file)
    assert set(k_preset) == set(k_file) and len(k_preset) > 100
    for ch in k_preset:
        np.testing.assert_array_equal(k_file[ch], k_preset[ch], err_msg=str(ch))
    for n in M_preset:
        np.testing.assert_array_equal(M_file[n], M_preset[n], err_msg=n)


def test_a_saved_map_that_splits_a_segment_is_told_what_to_map(addon, tmp_path):
    """An Auto-Rig Pro export with twist bones and a map saved for the *_stretch bones alone (as
    the preset was before it took ARP's twist bones): the retarget's notes name each upper arm
    and thigh that would turn about its middle, and the map that fixes it; the preset itself
    (fitted to the character) gives no notes and the upper arm turns at the shoulder."""
    res = synthetic_result(T=T, fps=FPS, seed=6, stature=SRC_STATURE, with_targets=False)
    src = _write_source(res)
    char, spec = styled_character("auto_rig_pro")
    path = tmp_path / "arp_stretch_only.json"
    bone_maps.save_bone_map(path, bone_maps.BoneMap("stretch_only", dict(bone_maps.preset("auto_rig_pro").bones)))
    _, _, notes = retarget_apply.retarget_onto(src, char, "file", str(path), "scaled", False)
    said = [n for n in notes if "starts the same segment" in n]
    assert len(said) == 4, notes
    assert any(n.startswith("'thigh_stretch.r' (right_hip) hangs under 'thigh_twist.r'") for n in said), said
    _, _, notes = retarget_apply.retarget_onto(src, char, "auto_rig_pro", None, "scaled", False)
    assert notes == []
    pos, _ = res.fk()
    M, _ = _evaluate(char)
    arm = _world_heads(char, M, "forearm_stretch.l") - _world_heads(char, M, "c_arm_twist_offset.l")
    src_arm = (pos[:, sk.J["left_elbow"]] - pos[:, sk.J["left_shoulder"]]) @ spec["F"].T
    cos = np.sum(rot.normalize(arm) * rot.normalize(src_arm), -1)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.1


def test_a_live_auto_rig_pro_rig_is_keyed_on_its_fk_controls(addon):
    """A live Auto-Rig Pro rig (deforming bones following FK controls through constraints, the
    limbs by their IK/FK switch; ``live_auto_rig_pro_character``): the guess keys its FK controls
    (``auto_rig_pro_fk``; the spine3 control it lacks folded, with a note), keys the switches
    (``ik_fk_switch`` of c_hand_ik / c_foot_ik) to FK in the new action without changing the rig,
    and the deforming arms and legs point where the performer's do.  Keyed on its deforming bones
    instead (the ``auto_rig_pro`` preset), the notes say that they follow constraints."""
    res = synthetic_result(T=T, fps=FPS, seed=3, stature=SRC_STATURE, with_targets=False)
    src = _write_source(res)
    char = live_auto_rig_pro_character()
    bmap, guess = retarget_apply.resolve_bone_map("auto", char)
    assert bmap.name == "auto_rig_pro_fk" and "spine3" not in bmap.bones
    assert [(g.joint, g.why) for g in guess if g.confidence < 0.5] == [
        ("spine3", "the rig has no 'c_spine_03.x': folded into its neighbours")]
    action, out, notes = retarget_apply.retarget_onto(src, char, "auto", None, "scaled", False)
    assert notes == ["spine3: no bone (the rig has no 'c_spine_03.x': folded into its neighbours)"], notes
    paths = {fc.data_path for fc in keying.action_fcurves(action, char)}
    for b in ("c_hand_ik.l", "c_hand_ik.r", "c_foot_ik.l", "c_foot_ik.r"):
        assert f'pose.bones["{b}"]["ik_fk_switch"]' in paths, b
    assert 'pose.bones["c_arm_fk.l"].rotation_quaternion' in paths
    assert 'pose.bones["c_root_master.x"].location' in paths
    assert not any("stretch" in p for p in paths)               # the deforming bones are not keyed
    pos, _ = res.fk()
    M, _ = _evaluate(char)
    worst = {}
    for bone, a, b in (("arm_stretch.l", "left_shoulder", "left_elbow"),
                       ("forearm_stretch.r", "right_elbow", "right_wrist"),
                       ("thigh_stretch.l", "left_hip", "left_knee"), ("leg_stretch.r", "right_knee", "right_ankle"),
                       ("spine_01.x", "spine1", "spine2")):
        d = _world_heads(char, M, {"arm_stretch.l": "forearm_stretch.l", "forearm_stretch.r": "hand.r",
                                   "thigh_stretch.l": "leg_stretch.l", "leg_stretch.r": "foot.r",
                                   "spine_01.x": "spine_02.x"}[bone]) - _world_heads(char, M, bone)
        cos = np.sum(rot.normalize(d) * rot.normalize(pos[:, sk.J[b]] - pos[:, sk.J[a]]), -1)
        worst[bone] = float(np.degrees(np.arccos(np.clip(cos, -1, 1))).max())
    assert max(worst.values()) < 0.1, worst
    # the switches are keys of the new action (FK, held), not a change to the rig
    for fc in keying.action_fcurves(action, char):
        if fc.data_path.endswith('["ik_fk_switch"]'):
            co = np.empty(2 * len(fc.keyframe_points), dtype=np.float32)
            fc.keyframe_points.foreach_get("co", co)
            assert np.all(co[1::2] == 1.0) and fc.keyframe_points[0].interpolation == 'CONSTANT'

    _, _, notes = retarget_apply.retarget_onto(src, char, "auto_rig_pro", None, "scaled", False)
    held = [n for n in notes if "follow constraints that set their rotation" in n]
    assert len(held) == 1 and held[0].startswith("21 of the bones this map keys"), notes
