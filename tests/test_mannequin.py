"""The mannequin mesh (core/mannequin.py): closed pieces, on the floor, sized by the body, rigid
with its bones, and above the floor where the solve keeps the feet."""
import os
from collections import Counter

import numpy as np
import pytest

from blender_manikin.core import mannequin as mq
from blender_manikin.core import pipeline
from blender_manikin.core import skeleton as sk

from blender_util import smooth_local_rotations

EXAMPLE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples",
                       "example_recording.csv")


def _polygons(m, piece=None):
    faces = m.faces if piece is None else m.faces[m.piece[m.faces[:, 0]] == piece]
    return [tuple(f[:3]) if f[3] == f[2] else tuple(f) for f in faces]


def _signed_volume(verts, polys):
    v = 0.0
    for p in polys:
        for i in range(1, len(p) - 1):
            v += np.dot(verts[p[0]], np.cross(verts[p[i]], verts[p[i + 1]])) / 6.0
    return v


@pytest.mark.parametrize("stature", [1.50, 1.75, 2.00])
def test_pieces_are_closed_outward_and_one_bone_each(stature):
    m = mq.mannequin_mesh(sk.make_body(stature))
    edges = Counter()
    for p in _polygons(m):
        for i in range(len(p)):
            edges[tuple(sorted((p[i], p[(i + 1) % len(p)])))] += 1
    assert set(edges.values()) == {2}                 # every edge between two faces: closed
    for k, name in enumerate(m.names):
        assert _signed_volume(m.verts, _polygons(m, k)) > 0, name       # normals point out
        assert len(set(m.bone[m.piece == k])) == 1, name               # rigid on one bone
    assert len(m.names) == sk.NUM_JOINTS                 # one piece per bone
    assert set(m.bone_names) == set(sk.JOINT_NAMES)


@pytest.mark.parametrize("stature,sole", [(1.50, 0.03), (1.75, 0.0), (2.00, 0.05)])
def test_rests_on_the_floor_and_reaches_the_stature(stature, sole):
    body = sk.make_body(sk.BodyMeasurements(stature=stature, sole=sole))
    m = mq.mannequin_mesh(body)
    assert abs(m.verts[:, 2].min()) < 1e-9            # the soles on z = 0
    assert abs(m.verts[:, 2].max() - (stature + sole)) < 1e-3       # the top of the head
    # the heel and the ball, where the solver keeps a foot on the floor, are over the sole
    P = body.rest_positions()
    for side in ("left", "right"):
        ball = P[sk.J[f"{side}_foot"]]
        feet = m.verts[np.isin(m.bone, [sk.J[f"{side}_ankle"], sk.J[f"{side}_foot"]])]
        near = np.linalg.norm(feet[:, :2] - ball[:2], axis=1) < 0.01 * stature
        assert near.any() and feet[near, 2].min() < 0.01 * stature
        # the body's proportions: about as wide as a person (shoulder to shoulder)
    width = m.verts[m.bone == sk.J["spine3"], 0]
    assert 0.17 * stature < width.max() - width.min() < 0.23 * stature


def test_mirror_symmetric_and_scales_with_the_body():
    body = sk.make_body(1.8)
    m = mq.mannequin_mesh(body)
    for k, name in enumerate(m.names):
        if name.startswith("left_"):
            other = m.names.index("right_" + name[5:])
            a, b = m.verts[m.piece == k], m.verts[m.piece == other]
            assert np.allclose(np.sort(a[:, 0]), np.sort(-b[:, 0]), atol=1e-9), name
            assert np.allclose(np.sort(a[:, 2]), np.sort(b[:, 2]), atol=1e-9), name
    cm = mq.mannequin_mesh(body.scaled(100.0))          # the same body in centimetres
    assert np.allclose(cm.verts, 100.0 * m.verts, atol=1e-6)
    assert np.array_equal(cm.faces, m.faces)


def test_posed_vertices_move_rigidly_with_their_bones():
    body = sk.make_body(1.7)
    m = mq.mannequin_mesh(body)
    T = 12
    local = smooth_local_rotations(T, seed=3)
    root = np.tile(body.root_rest, (T, 1)) + np.linspace(0, 0.5, T)[:, None] * [1.0, 0.0, 0.0]
    pos, world = sk.forward_kinematics(local, root, body)
    posed = mq.posed_vertices(m, world, pos, body)
    assert posed.shape == (T,) + m.verts.shape
    # the rest pose gives the mesh back
    rest = mq.posed_vertices(m, np.tile(np.eye(3), (1, sk.NUM_JOINTS, 1, 1)), body.rest_positions()[None], body)
    assert np.allclose(rest[0], m.verts, atol=1e-12)
    # each piece keeps its shape, and its place relative to its bone's joint and its child
    for k in range(len(m.names)):
        idx = np.nonzero(m.piece == k)[0][::7]
        d0 = np.linalg.norm(m.verts[idx, None] - m.verts[None, idx], axis=-1)
        dt = np.linalg.norm(posed[:, idx, None] - posed[:, None, idx], axis=-1)
        assert np.abs(dt - d0).max() < 1e-9
    knee, shank = sk.J["left_knee"], m.names.index("left_shank")
    v = m.verts[m.piece == shank]
    for t in (0, T - 1):
        expect = (v - body.rest_positions()[knee]) @ world[t, knee].T + pos[t, knee]
        assert np.allclose(posed[t, m.piece == shank], expect, atol=1e-9)


def test_solved_feet_keep_the_mannequin_out_of_the_floor():
    """The solve keeps each foot's heel and ball above the floor (pipeline.keep_feet_above_floor);
    the mannequin's feet are built on those points, so on a real take no vertex of it goes into the
    floor further than the sink the solver allows."""
    from blender_manikin.core.solve import SolveSettings, solve_recording
    out = solve_recording(EXAMPLE, SolveSettings(fps=30.0))
    res = out.result
    pos, world = res.fk()
    m = mq.mannequin_mesh(res.body)
    low = mq.posed_vertices(m, world, pos, res.body)[..., 2].min(axis=1)        # (T,) lowest point
    assert low.min() > -(pipeline.FOOT_SINK + 0.0005)
    # and a foot on the floor shows on it: its lowest point within a centimetre of it
    assert np.percentile(low, 50) < 0.01


@pytest.mark.parametrize("joint", ["left_elbow", "left_wrist", "right_knee", "left_foot"])
def test_a_zero_length_bone_gives_a_round_piece_not_nans(joint):
    body = sk.make_body(1.7)
    off = body.offsets.copy()
    off[sk.J[joint]] = 0.0                        # the segment ending at this joint has no length
    m = mq.mannequin_mesh(sk.Body.from_offsets(off, body.root_rest, stature=1.7))
    assert np.isfinite(m.verts).all()
    assert np.isfinite(mq.mannequin_mesh(body).verts).all()


def test_a_body_with_nan_offsets_is_an_error():
    body = sk.make_body(1.7)
    off = body.offsets.copy()
    off[sk.J["head"]] = np.nan
    with pytest.raises(ValueError, match="finite"):
        mq.mannequin_mesh(sk.Body.from_offsets(off, body.root_rest, stature=1.7))
