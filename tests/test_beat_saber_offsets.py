"""Where Beat Saber holds the saber: the presets by game version, runtime and controller, and a
replay's own saber offsets (the BSOR saber-offsets block).  Needs no ../shared."""
import struct

import numpy as np
import pytest

from blender_manikin.core import device_offsets as do
from blender_manikin.core import solve as cs
from blender_manikin.core.formats import load_recording
from blender_manikin.core.io_bsor import parse_bsor, parse_game_version
from blender_manikin.core.rotations import quat_to_matrix, matrix_to_quat

from fixtures_recordings import bsor_bytes, unity_pose


def _angle_deg(Ra, Rb):
    return float(np.degrees(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1, 1))))


@pytest.mark.parametrize("raw,measured,tol_mm,tol_deg", [
    # Beat Games' measured OpenVR pose in the OpenXR grip pose (Unity axes, right hand), the
    # game's kValveIndexOriginOffsetToLegacy and kHTCViveOriginOffsetToLegacy
    ("index_knuckles", ((0.134097934, 0.0174996667, 0.00493389927, 0.990801275), (0.004575, -0.01995, 0.129387)),
     1.0, 1.0),
    ("vive_wand", ((0.0436193869, 0.0, 0.0, 0.999048233), (0.000484, 0.00692, 0.09826)), 1.0, 0.1),
])
@pytest.mark.parametrize("side", ["left", "right"])
def test_raw_to_grip_presets_agree_with_the_games_own_measurement(raw, measured, tol_mm, tol_deg, side):
    """The SteamVR render-model numbers behind index_knuckles and vive_wand, against an independent
    measurement (and the Unity-axes conversion and left-hand mirroring used for the game's numbers)."""
    R, p = do._unity_pose(*measured, side=side)               # raw pose in the grip pose
    Ri, pi = do._inverse(do._RAW_TO_GRIP[raw][side])
    assert np.linalg.norm(p - pi) * 1000 < tol_mm
    assert _angle_deg(R, Ri) < tol_deg


@pytest.mark.parametrize("controller,hmd,platform,tracking,version,want", [
    ("OpenVR Controller(Knuckles Right) - Right", "VIVE Pro 2", "steam", "OpenVR", "1.29.1_457", "beat_saber"),
    ("OpenVR Controller(Knuckles Right) - Right", "Valve Index", "steam", "OpenVR", "1.34.2_1", "beat_saber_xr"),
    ("Oculus Touch", "Quest 2", "steam", "OpenVR", "1.29.1_1", "beat_saber_touch"),       # Touch on SteamVR
    ("Oculus Touch", "Quest 2", "oculus", "Oculus", "1.29.1_1", "beat_saber_oculus"),    # the Oculus runtime
    ("Meta Quest Touch Plus (Right Controller)", "Quest 3", "oculus", "Oculus", "1.37.0_1", "beat_saber_xr_touch"),
    ("Unknown", "Oculus Quest 2", "oculus", "Oculus", "1.27.0_1", "beat_saber_oculus"),  # the headset decides
    ("OpenVR Controller(vive_controller)", "Quest 2", "steam", "OpenVR", "1.29.1_1", "beat_saber_vive"),
    ("OpenVR Controller(vive_controller)", "Vive", "steam", "OpenVR", "1.29.4_1", "beat_saber_xr_vive"),
    ("Test Controller", "Test HMD", "steam", "OpenVR", "oops", "beat_saber"),            # unreadable version
    ("PICO 4 Controller", "PICO 4", "steam", "OpenXR", "1.34.2_1", "openxr_generic"),    # no offsets: the grip
])
def test_the_preset_follows_version_runtime_and_controller(tmp_path, controller, hmd, platform, tracking,
                                                           version, want):
    t = np.arange(30) / 90.0
    data = bsor_bytes(t, *(unity_pose(d, t) for d in ("head", "left_hand", "right_hand")),
                      info=dict(controller=controller, hmd=hmd, platform=platform, trackingSystem=tracking,
                                gameVersion=version))
    path = tmp_path / "c.bsor"
    path.write_bytes(data)
    rec = load_recording(path)
    assert rec.metadata["offsets"] == want
    assert cs.resolve_offsets("auto", rec) == want and cs.resolve_offsets("quest_touch", rec) == "quest_touch"
    newer = [w for w in rec.warnings if w.startswith("Beat Saber ")]
    assert bool(newer) == ((parse_game_version(version) or (0,)) >= (1, 29, 4))
    if newer:
        assert "does not record the player's saber offsets" in newer[0] and version.split("_")[0] in newer[0]


def _tail(saber=None, custom=True):
    """The blocks after the frames: two notes (a good cut, a miss), a wall, a height, a pause, then
    the saber offsets ``(left pos, left quat xyzw, right pos, right quat xyzw)`` and custom data."""
    out = bytearray(struct.pack("<Bi", 2, 2))
    out += struct.pack("<iffi", 31234, 1.0, 0.5, 0) + bytes(72)          # good: 72 bytes of cut info
    out += struct.pack("<iffi", 31235, 2.0, 1.5, 2)                      # miss: none
    out += struct.pack("<Bi", 3, 1) + struct.pack("<ifff", 101, 0.9, 3.0, 2.5)
    out += struct.pack("<Bi", 4, 1) + struct.pack("<ff", 1.7, 0.0)
    out += struct.pack("<Bi", 5, 1) + struct.pack("<qf", 3, 4.0)
    if saber is not None:
        out += struct.pack("<B14f", 6, *np.concatenate([np.ravel(a) for a in saber]))
    if custom:
        key = b"reesabers:tricks-replay"
        out += struct.pack("<Bii", 7, 1, len(key)) + key + struct.pack("<i", 3) + b"abc"
    return bytes(out)


def _compose_unity(pose, S_pos, S_quat_xyzw):
    """``pose (N, 7)`` (Unity px, py, pz, qx, qy, qz, qw) times the local pose S: ``pose · S``."""
    q = np.concatenate([pose[:, 6:7], pose[:, 3:6]], 1)
    R = quat_to_matrix(q)
    x, y, z, w = S_quat_xyzw
    RS = quat_to_matrix(np.array([w, x, y, z]))
    p = pose[:, :3] + np.einsum("nij,j->ni", R, np.asarray(S_pos))
    qq = matrix_to_quat(R @ RS)
    return np.concatenate([p, qq[:, 1:], qq[:, :1]], 1)


def _hand_targets(rec, offsets):
    tp, tr = {}, {}
    for d in ("left_hand", "right_hand"):
        s = rec.streams[d]
        tp[d], tr[d] = do.apply_offsets(s.pos, quat_to_matrix(s.quat), offsets, device=d)
    return tp, tr


# a player's own saber offsets (Unity axes): tilted 25° and 3 cm off the game's defaults
_S = {"left": ((-0.03, -0.02, 0.11), (0.2164, 0.0, 0.0, 0.9763)),
      "right": ((0.03, -0.02, 0.11), (0.2164, 0.0, 0.0, 0.9763))}


@pytest.mark.parametrize("version,node", [("1.34.2_1", "openxr"), ("1.29.1_1", "openvr_index")])
def test_a_replays_own_saber_offsets_recover_the_controller(version, node):
    """A replay whose sabers sit at the player's own offsets from the controller pose the game read
    is solved from that controller pose: the same wrists as the controller poses themselves with
    that controller's offsets (OpenXR grip: openxr_generic; an Index's OpenVR pose: index_knuckles)."""
    t = (np.arange(1, 61) / 90.0).astype(np.float32).astype(np.float64)
    head = unity_pose("head", t)
    node_poses = {d: unity_pose(d, t) for d in ("left_hand", "right_hand")}
    sabers = {d: _compose_unity(node_poses[d], *_S[d.split("_")[0]]) for d in node_poses}
    info = dict(gameVersion=version, controller="OpenVR Controller(Knuckles Right) - Right")
    saber_block = [np.array(_S["left"][0]), np.array(_S["left"][1]), np.array(_S["right"][0]),
                   np.array(_S["right"][1])]
    rec = parse_bsor(bsor_bytes(t, head, sabers["left_hand"], sabers["right_hand"], info=info,
                                extra_tail=_tail(saber_block)), path="own.bsor")
    off = cs.resolve_offsets("auto", rec)
    assert isinstance(off, dict) and off["name"] == "beat_saber_replay"
    assert rec.metadata["saber_offsets"]["right"]["pos"] == pytest.approx([0.03, -0.02, 0.11], abs=1e-6)
    assert not [w for w in rec.warnings if w.startswith("Beat Saber ")]     # nothing assumed
    note = cs.offsets_note("auto", off, rec)
    assert "saber offsets the replay records" in note and version.split("_")[0] in note
    plain = parse_bsor(bsor_bytes(t, head, node_poses["left_hand"], node_poses["right_hand"], info=info),
                       path="controller.bsor")
    want_p, want_R = _hand_targets(plain, "openxr_generic" if node == "openxr" else "index_knuckles")
    got_p, got_R = _hand_targets(rec, off)
    for d in want_p:
        assert np.abs(got_p[d] - want_p[d]).max() < 2e-5                          # float32 file
        assert max(_angle_deg(a, b) for a, b in zip(got_R[d], want_R[d])) < 0.01
    # the game's defaults instead of the player's offsets would put the wrists elsewhere
    default_p, _ = _hand_targets(rec, cs.resolve_offsets("auto", plain))
    assert np.linalg.norm(default_p["right_hand"] - want_p["right_hand"], axis=1).min() > 0.02


@pytest.mark.parametrize("tail,warned", [
    (_tail(None), False),                                                   # no block 6: the presets
    (_tail([np.zeros(3), np.array([0, 0, 0, 1.0]), np.zeros(3), np.array([0, 0, 0, 1.0])]), False),  # empty
    (_tail([np.array([0, 0, 0.9]), np.array([0, 0, 0, 1.0]), np.zeros(3), np.array([0, 0, 0, 1.0])]), True),
    (_tail(None, custom=False)[:-7], True),                                 # cut inside the pauses block
    (_tail(None, custom=False) + b"\x06\x00\x00", True),                    # a saber block cut short
])
def test_a_tail_without_usable_saber_offsets_falls_back_to_the_presets(tail, warned):
    t = np.arange(1, 31) / 90.0
    rec = parse_bsor(bsor_bytes(t, *(unity_pose(d, t) for d in ("head", "left_hand", "right_hand")),
                                info=dict(gameVersion="1.29.1_1"), extra_tail=tail), path="tail.bsor")
    assert rec.metadata["offsets"] == "beat_saber" and "saber_offsets" not in rec.metadata
    assert rec.streams["left_hand"].time.size == 30                           # the motion is all there
    hit = [w for w in rec.warnings if "saber offsets" in w or "blocks after the motion frames" in w]
    assert bool(hit) == warned
    if warned:
        assert "default" in hit[0]


def test_new_presets_are_rigid_and_named():
    for name in ("beat_saber_vive", "beat_saber_oculus", "beat_saber_xr", "beat_saber_xr_touch", "beat_saber_xr_vive"):
        p = do.get_preset(name)
        assert p["name"] == name and "Beat Saber" in p["description"]
        for side in ("left", "right"):
            e = p["devices"][f"{side}_hand"]
            assert np.linalg.norm(e["rot"]) == pytest.approx(1.0) and np.linalg.norm(e["pos"]) < 0.3
    with pytest.raises(ValueError, match="unknown controller pose"):
        do.beat_saber_replay_offsets(_S, node="steam")
