"""LaFAN1 and 100STYLE joint maps, and joint-map files (JSON) for other rigs."""
import json
import warnings

import numpy as np
import pytest

from blender_manikin.core import skeleton
from blender_manikin.core import joint_maps as jmod
from blender_manikin.core.bvh import read_bvh, write_bvh
from blender_manikin.core.joint_maps import clip_to_body_motion, detect_joint_map, rest_pose_report

from fixtures_bvh import bandai_clip, cmu_clip, lafan1_clip, mixamo_clip, style100_clip, synthetic_motion
from test_joint_maps import _check_roundtrip

J = skeleton.J


@pytest.fixture(scope="module")
def motion():
    return synthetic_motion(frames=90, seed=3)


def _through_file(clip, tmp_path, fname):
    write_bvh(tmp_path / fname, clip)
    return read_bvh(tmp_path / fname)


def test_lafan1_layout_roundtrip(motion, tmp_path):
    """Body -> LaFAN1-layout BVH (cm, Y-up, ZYX, bones along local +X: not a T-pose) -> map:
    positions and the six end orientations come back."""
    body, _, _, pos, rot = motion
    clip = _through_file(lafan1_clip(body, pos, rot), tmp_path, "walk1_subject1.bvh")
    assert clip.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
    rep = rest_pose_report(clip, "lafan1")
    assert rep["spine"] > 60 and rep["left_leg"] > 60            # zero pose is not a T-pose
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = clip_to_body_motion(clip)                            # detected from the names
    assert m.joint_map == "lafan1" and m.unit_scale == 0.01 and m.fps == 30.0
    assert np.abs(m.positions - pos).max() < 1e-3                # within 1 mm
    _check_roundtrip(m, pos, rot, body)


def test_100style_layout_roundtrip(motion, tmp_path):
    """Body -> 100STYLE-layout (Xsens MVN) BVH (cm, Y-up, YXZ, T-pose rest, 60 fps) -> map."""
    body, _, _, pos, rot = motion
    clip = _through_file(style100_clip(body, pos, rot), tmp_path, "Aeroplane_FW.bvh")
    assert clip.channels[1] == ("Yrotation", "Xrotation", "Zrotation")
    assert max(rest_pose_report(clip, "100style").values()) < 1e-6
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = clip_to_body_motion(clip)
    assert m.joint_map == "100style" and m.unit_scale == 0.01 and m.fps == 60.0
    assert np.abs(m.positions - pos).max() < 1e-3
    _check_roundtrip(m, pos, rot, body)


def test_detection_tells_the_rigs_apart(motion):
    """LaFAN1 shares the cgspeed names but has LeftToe, not LeftToeBase; 100STYLE has its own
    names; Bandai, CMU and Mixamo are still detected as before."""
    body, _, _, pos, rot = motion
    p, r = pos[:2], rot[:2]
    for clip, name in ((lafan1_clip(body, p, r), "lafan1"), (style100_clip(body, p, r), "100style"),
                       (bandai_clip(body, p, r), "bandai"), (cmu_clip(body, p, r), "cmu"),
                       (mixamo_clip(body, p, r), "mixamo")):
        assert detect_joint_map(clip.joint_names, clip.parents).name == name
        assert detect_joint_map(clip.joint_names).name == name
    lafan = lafan1_clip(body, p, r)
    assert "LeftToeBase" in jmod.CMU.missing(lafan.joint_names)


def _lafan1_file_dict():
    """The built-in LaFAN1 map written as a joint-map file."""
    spine = ["Hips", "Spine", "Spine1", "Spine2", "Neck"]
    pos = {"pelvis": "Hips", "neck": "Neck", "head": "Head",
           "spine1": {"chain": spine, "at": 0.25}, "spine2": {"chain": spine, "at": 0.5},
           "spine3": {"chain": spine, "at": 0.75}}
    for side, S in (("left", "Left"), ("right", "Right")):
        pos.update({f"{side}_hip": f"{S}UpLeg", f"{side}_knee": f"{S}Leg", f"{side}_ankle": f"{S}Foot",
                    f"{side}_foot": f"{S}Toe", f"{side}_collar": f"{S}Shoulder",
                    f"{side}_shoulder": f"{S}Arm", f"{side}_elbow": f"{S}ForeArm", f"{side}_wrist": f"{S}Hand"})
    ori = {
        "pelvis": {"joint": "Hips", "primary": "+x", "secondary": {"bone": ["RightUpLeg", "LeftUpLeg"]}},
        "head": {"joint": "Head", "primary": "+x", "secondary": "+y"},
        "left_wrist": {"joint": "LeftHand", "primary": [1, 0, 0], "secondary": "+z"},
        "right_wrist": {"joint": "RightHand", "primary": "x", "secondary": "-z"},
        "left_ankle": {"joint": "LeftFoot", "primary": {"bone": ["LeftFoot", "LeftToe"]}, "secondary": "-z"},
        "right_ankle": {"joint": "RightFoot", "primary": {"bone": ["RightFoot", "RightToe"]}, "secondary": "-z"},
    }
    return {"name": "my_lafan", "units": "cm", "up": "y", "forward": "z", "rest_is_tpose": False,
            "positions": pos, "orientations": ori}


def test_a_joint_map_file_reproduces_the_builtin_map(motion, tmp_path):
    body, _, _, pos, rot = motion
    clip = lafan1_clip(body, pos[:40], rot[:40])
    f = tmp_path / "lafan.json"
    f.write_text(json.dumps(_lafan1_file_dict()))
    jm = jmod.load_joint_map(f)
    assert jm.name == "my_lafan" and jm.unit_scale == 0.01
    a = clip_to_body_motion(clip, "lafan1")
    b = clip_to_body_motion(clip, str(f))                        # a path is accepted too
    assert np.abs(a.positions - b.positions).max() < 1e-9
    for n in jmod.ORIENTED_JOINTS:
        assert np.abs(a.rotations[n] - b.rotations[n]).max() < 1e-9, n
    # a T-pose rig needs positions only: orientations default to the rest axes (ankles: bone to the toe)
    c = style100_clip(body, pos[:40], rot[:40])
    minimal = {"positions": {n: jmod.STYLE100.positions[n].joints[0] if jmod.STYLE100.positions[n].kind == "joint"
                             else {"lerp": list(jmod.STYLE100.positions[n].joints), "t": jmod.STYLE100.positions[n].t}
                             if jmod.STYLE100.positions[n].kind == "lerp"
                             else {"chain": list(jmod.STYLE100.positions[n].joints), "at": jmod.STYLE100.positions[n].t}
                             for n in skeleton.JOINT_NAMES}}
    g = tmp_path / "xsens.json"
    g.write_text(json.dumps(minimal))
    m1, m2 = clip_to_body_motion(c, "100style"), clip_to_body_motion(c, str(g))
    assert m2.joint_map == "xsens" and m2.unit_scale == 0.01             # units detected
    assert np.abs(m1.positions - m2.positions).max() < 1e-9
    for n in jmod.ORIENTED_JOINTS:
        assert np.abs(m1.rotations[n] - m2.rotations[n]).max() < 1e-9, n


@pytest.mark.parametrize("change, message", [
    (lambda d: d["positions"].update(left_toe="LeftToe"), r"unknown body joint\(s\) left_toe"),
    (lambda d: d["positions"].pop("right_wrist"), r"missing body joint\(s\) right_wrist"),
    (lambda d: d["positions"].update(spine1={"chain": ["Hips"], "at": 0.25}), r"positions.spine1: bad position"),
    (lambda d: d["positions"].update(spine2={"lerp": ["Hips", "Spine"], "t": 2}), r"positions.spine2: bad position"),
    (lambda d: d["orientations"]["head"].update(primary="up"), r"orientations.head.primary: bad axis"),
    (lambda d: d["orientations"].pop("pelvis"), r"orientations.pelvis is needed"),
    (lambda d: d.update(units="furlong"), r"units must be"),
    (lambda d: d.update(up="y", forward="-y"), r"must be different axes"),
    (lambda d: d.update(colour="red"), r"unknown field\(s\) colour"),
])
def test_malformed_joint_map_files(tmp_path, change, message):
    d = _lafan1_file_dict()
    change(d)
    f = tmp_path / "bad_map.json"
    f.write_text(json.dumps(d))
    with pytest.raises(ValueError, match=message) as e:
        jmod.load_joint_map(f)
    assert str(e.value).startswith(str(f))


def test_joint_map_file_not_json(tmp_path):
    f = tmp_path / "broken.json"
    f.write_text('{"positions": {\n  "pelvis": "Hips",,\n}}')
    with pytest.raises(ValueError, match=r"broken.json: not valid JSON \(line 2"):
        jmod.load_joint_map(f)


def test_sources_file_accepts_a_joint_map_file(tmp_path):
    from blender_manikin.training.dataset import load_sources, source_licence
    (tmp_path / "maps").mkdir()
    (tmp_path / "maps" / "lafan.json").write_text(json.dumps(_lafan1_file_dict()))
    src = tmp_path / "sources.json"
    src.write_text(json.dumps([
        {"path": "a", "name": "studio", "joint_map": "maps/lafan.json", "licence": "ours"},
        {"path": "b", "name": "LaFAN1", "joint_map": "lafan1"},
        {"path": "c", "name": "100STYLE", "joint_map": "100STYLE "}]))
    s = load_sources(src)
    assert s[2].joint_map == "100style"            # a built-in map's name in any case
    assert s[0].joint_map == str(tmp_path / "maps" / "lafan.json")
    assert "joint_map_sha1" in s[0].read_options()
    assert source_licence(s[1]).startswith("CC BY-NC-ND 4.0")
    assert source_licence(s[2]).startswith("CC BY 4.0")
    bad = _lafan1_file_dict()
    del bad["positions"]["head"]
    (tmp_path / "maps" / "lafan.json").write_text(json.dumps(bad))
    with pytest.raises(ValueError, match=r"sources.json line 1: source 1: joint_map file: .*lafan.json, line 1: "
                                         r"positions: missing body joint\(s\) head"):
        load_sources(src)


def test_a_misspelt_joint_in_a_joint_map_file_is_named_with_its_entry(motion, tmp_path):
    """A joint name in a joint-map file that the skeleton lacks (``LeftHnad``) is refused naming
    the clip, the map's file and the entries that use it, with the skeleton's joints (it was a
    ``KeyError: "walk: source joint 'LeftHnad' not found"`` per clip, naming neither)."""
    body, _, _, pos, rot = motion
    clip = lafan1_clip(body, pos[:10], rot[:10])
    d = _lafan1_file_dict()
    d["positions"]["left_wrist"] = "LeftHnad"
    d["orientations"]["left_wrist"]["joint"] = "LeftHnad"
    d["orientations"]["left_ankle"]["primary"] = {"bone": ["LeftFoot", "LeftToee"]}
    f = tmp_path / "studio.json"
    f.write_text(json.dumps(d))
    with pytest.raises(ValueError, match=r"joint map 'my_lafan' \(joint-map file studio\.json\) names joint\(s\) "
                                         r"this skeleton does not have: positions\.left_wrist: 'LeftHnad'; "
                                         r"orientations\.left_wrist: 'LeftHnad'; orientations\.left_ankle: "
                                         r"'LeftToee' \(its joints: Hips, .*LeftHand"):
        clip_to_body_motion(clip, str(f))


def _toes_to_end_sites(clip):
    """The clip with its ``LeftToeBase`` / ``RightToeBase`` leaf joints replaced by an End Site of
    the same OFFSET on the foot: the Perception Neuron (Axis Neuron BVH) layout, whose feet end in
    an End Site with no toe joint (``RightFoot { ... End Site { OFFSET 0 -7.85 17.85 } }``)."""
    from blender_manikin.core.bvh import BvhClip
    drop = [clip.joint_index(n) for n in ("LeftToeBase", "RightToeBase")]
    keep = [j for j in range(clip.num_joints) if j not in drop]
    ends = clip.end_sites.copy()
    for j in drop:
        ends[clip.parents[j]] = clip.offsets[j]
    new = {j: k for k, j in enumerate(keep)}
    cols = np.concatenate([np.arange(len(clip.channels[j])) + clip.channel_starts[j] for j in keep])
    return BvhClip(clip.name, [clip.joint_names[j] for j in keep],
                   [new[int(clip.parents[j])] if clip.parents[j] >= 0 else -1 for j in keep],
                   clip.offsets[keep], [clip.channels[j] for j in keep], clip.frame_time,
                   clip.motion[:, cols], end_sites=ends[keep])


def _map_file_dict(jm):
    """A joint-map file's dict with a built-in map's positions (its orientations left to the defaults)."""
    def point(p):
        if p.kind == "joint":
            return p.joints[0]
        return {"lerp": list(p.joints), "t": p.t} if p.kind == "lerp" else {"chain": list(p.joints), "at": p.t}
    return {"name": "neuron_like", "units": "cmu", "foot_pitch": "auto",
            "positions": {n: point(jm.positions[n]) for n in skeleton.JOINT_NAMES}}


def test_a_joint_map_file_may_name_an_end_site(motion, tmp_path):
    """A rig whose feet end in an End Site with no toe joint (Perception Neuron's Axis Neuron BVH,
    older Biovision rigs) is mapped by a joint-map file naming ``"LeftFoot/End Site"`` as the ball
    of the foot: the same body motion as the CMU map on the rig with its toe joints (before, no map
    could name an End Site: "names joint(s) this skeleton does not have: positions.left_foot")."""
    body, _, _, pos, rot = motion
    clip = _toes_to_end_sites(_through_file(cmu_clip(body, pos, rot), tmp_path, "take.bvh"))
    clip = _through_file(clip, tmp_path, "neuron_take.bvh")
    assert "LeftToeBase" not in clip.joint_names
    d = _map_file_dict(jmod.CMU)
    d["positions"]["left_foot"] = "LeftFoot/End Site"
    d["positions"]["right_foot"] = "RightFoot/End Site"
    f = tmp_path / "neuron.json"
    f.write_text(json.dumps(d))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = clip_to_body_motion(clip, str(f))
    _check_roundtrip(m, pos, rot, body)
    with pytest.raises(ValueError, match=r"give it as the joint map"):   # detection says how
        detect_joint_map(clip.joint_names, clip.parents)
    d["orientations"] = {"left_ankle": {"joint": "LeftFoot/End Site", "primary": "+y", "secondary": "+x"}}
    f.write_text(json.dumps(d))
    with pytest.raises(ValueError, match=r"orientations\.left_ankle: 'LeftFoot/End Site' is an End Site, which "
                                         r"has no rotation"):
        clip_to_body_motion(clip, str(f))


def test_a_files_two_parallel_local_axes_are_refused_naming_the_file_and_line(tmp_path):
    """An orientation whose primary and secondary are the same local axis (a typo in the file) is
    the file's fault, whatever the rig: refused on loading, naming the file and the line (before: it
    loaded, and solving blamed the rig and told to give the joint map 'rokoko')."""
    d = _lafan1_file_dict()
    d["orientations"]["head"]["secondary"] = [2, 0, 0]          # primary is "+x"
    f = tmp_path / "typo.json"
    f.write_text(json.dumps(d, indent=1))
    line = f.read_text().splitlines().index('   "secondary": [') + 1
    with pytest.raises(ValueError, match=rf"typo\.json, line {line}: orientations\.head\.secondary: \[2, 0, 0\] "
                                         r"is parallel to primary '\+x'") as e:
        jmod.load_joint_map(f)
    assert "rokoko" not in str(e.value)
