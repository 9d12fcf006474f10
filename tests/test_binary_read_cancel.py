"""A cancel (Esc in Blender) stops the binary and clip readers mid-read: C3D markers
(``core/io_c3d.py``), Unity ``.anim`` clips (``core/io_unity_anim.py``, its fast key reader and its
general YAML parser) and XROR (``core/io_xror.py``, while its child process decodes the frames)
call ``recording.read_check`` between chunks, as the text readers do; the cancel's exception
comes out of the reader itself (no timing: the check raises at its Nth call)."""
import os
import traceback

import numpy as np
import pytest

from blender_manikin.core import io_c3d, io_unity_anim, io_xror, recording as rec
from fixtures_c3d import write_c3d
from test_io_unity_anim import anim_text, motion


class Cancelled(Exception):
    pass


def _read_cancelled(read, at):
    """Run ``read()`` inside ``cancellable_reads`` with a check that raises at its ``at``-th call;
    returns the checks made and the traceback's (file name, function) pairs."""
    calls = []

    def check():
        calls.append(1)
        if len(calls) == at:
            raise Cancelled()
    with pytest.raises(Cancelled) as e, rec.cancellable_reads(check):
        read()
    return len(calls), [(os.path.basename(f.filename), f.name) for f in traceback.extract_tb(e.tb)]


@pytest.mark.parametrize("floats", [False, True])
def test_c3d_read_stops_between_chunks_of_frames(tmp_path, monkeypatch, floats):
    monkeypatch.setattr(rec, "CHECK_ROWS", 8)
    pts = np.random.default_rng(0).normal(size=(64, 5, 3)) * 100
    path = write_c3d(tmp_path / "take.c3d", [f"M{k}" for k in range(5)], pts, floats=floats)
    whole = io_c3d.read_c3d(path)                          # the chunks read as the whole did
    assert np.allclose(whole.points, pts, atol=0.1)
    calls, frames = _read_cancelled(lambda: io_c3d.read_c3d(path), at=3)
    assert calls == 3 and ("io_c3d.py", "read_c3d") in frames


@pytest.mark.parametrize("fast", [True, False])
def test_unity_anim_read_stops_between_chunks_of_keys(tmp_path, monkeypatch, fast):
    t, objs = motion(n=120)
    text = anim_text({p: {"time": t, "pos": pq[0], "quat": pq[1]} for p, pq in objs.items()})
    (tmp_path / "take.anim").write_text(text)
    one = io_unity_anim.read_unity_anim(tmp_path / "take.anim")
    monkeypatch.setattr(rec, "CHECK_ROWS", 7)
    cut = io_unity_anim.read_unity_anim(tmp_path / "take.anim")    # the keys read in chunks read the same
    for d in one.streams:
        assert np.array_equal(one.streams[d].time, cut.streams[d].time)
        assert np.array_equal(one.streams[d].pos, cut.streams[d].pos)
    calls, frames = _read_cancelled(lambda: io_unity_anim.parse_unity_yaml(text, fast=fast), at=3)
    assert calls == 3 and any(f == "io_unity_anim.py" for f, _ in frames)
    if fast:
        assert ("io_unity_anim.py", "_key_numbers") in frames


def test_xror_read_stops_while_the_decoder_runs(tmp_path, monkeypatch):
    pytest.importorskip("bson")
    pytest.importorskip("fpzip")
    from test_xror import _xror
    data, _t, _pose = _xror()
    path = tmp_path / "take.xror"
    path.write_bytes(data)
    monkeypatch.setattr(io_xror, "DECODER_POLL_S", 0.001)   # the child process takes longer to start
    started = []
    real = __import__("subprocess").Popen

    def popen(*a, **k):
        started.append(real(*a, **k))
        return started[-1]
    monkeypatch.setattr("subprocess.Popen", popen)
    calls, frames = _read_cancelled(lambda: io_xror.read_xror(path), at=1)
    assert calls == 1 and ("io_xror.py", "decompress_isolated") in frames
    assert len(started) == 1 and started[0].returncode is not None      # the decoder was ended


def test_npy_keypoints_stop_between_the_load_and_the_steps_after_it(tmp_path):
    from blender_manikin.core import io_keypoints
    X = np.random.default_rng(0).normal(size=(1, 33, 3)) * 0.3 + np.sin(np.arange(60) / 30.0)[:, None, None]
    np.save(tmp_path / "kp.npy", X)
    read = lambda: io_keypoints.read_keypoints(tmp_path / "kp.npy", layout="mediapipe33", units="m", rate=30)  # noqa: E731
    read()                                                 # it reads outside a cancellable block
    calls, frames = _read_cancelled(read, at=2)
    assert calls == 2 and ("io_keypoints.py", "_one_person") in frames
