"""The format registry (core/formats.py): readers by extension or content, writers, and what
the command line derives from it."""
import os
import shutil

import numpy as np
import pytest

from blender_manikin.core import formats
from blender_manikin.core.recording import RecordingError

from fixtures_recordings import synthetic_bsor

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def test_readers_by_extension_and_by_content(tmp_path):
    assert formats.input_extensions() == (".csv", ".bsor", ".xror", ".json", ".jsonl", ".ndjson", ".npy", ".npz",
                                          ".trc", ".c3d", ".anim")
    assert [f.name for f in formats.READERS.values() if f.kind == "keypoints"] == ["keypoints", "keypoints_json"]
    assert formats.reader_for("x.CSV").name == "csv" and formats.reader_for("y.bsor").name == "bsor"
    # a replay saved under another name is still recognised by its magic number
    path = tmp_path / "replay.dat"
    path.write_bytes(synthetic_bsor()[0])
    assert formats.reader_for(path).name == "bsor"
    rec = formats.load_recording(path)
    assert set(rec.devices) == {"head", "left_hand", "right_hand"}
    txt = tmp_path / "take.txt"
    shutil.copy(EXAMPLE, txt)
    assert formats.reader_for(txt).name == "csv"
    assert formats.load_recording(txt).devices == formats.load_recording(EXAMPLE).devices
    other = tmp_path / "notes.txt"
    other.write_text("hello\n")
    expected = r"notes.txt.*unsupported file type .\.txt.: expected .csv \(native or wide-layout CSV\)"
    with pytest.raises(RecordingError, match=expected):
        formats.load_recording(other)
    with pytest.raises(RecordingError, match="no such file"):
        formats.load_recording(tmp_path / "missing.csv")
    # keypoints are no tracker recording: the message says how to solve them
    import numpy as np
    np.save(tmp_path / "poses.npy", np.zeros((4, 17, 3)))
    with pytest.raises(RecordingError, match="poses.npy: 3D keypoints, not a tracker recording: solve it as keypoints"):
        formats.load_recording(tmp_path / "poses.npy")


def test_offsets_default_per_format():
    assert formats.default_offsets("a.bsor") == "beat_saber" and formats.default_offsets("a.csv") == "none"
    assert formats.default_offsets("a.unknown") == "none"


def test_npz_writer(tmp_path):
    from blender_manikin.core.solve import SolveSettings, solve_recording
    res = solve_recording(EXAMPLE, SolveSettings(fps=30.0)).result
    path = formats.WRITERS["npz"].write(tmp_path / "a.npz", res, source="example_recording.csv")
    with np.load(path) as z:
        assert z["positions"].shape == (res.num_frames, 22, 3) and z["rotations"].shape == (res.num_frames, 22, 4)
        assert np.allclose(z["positions"], res.positions, atol=1e-5)
        assert list(z["joints"])[0] == "pelvis" and float(z["fps"]) == 30.0
        assert z["contacts"].shape == (res.num_frames, 2) and str(z["source"]) == "example_recording.csv"
    assert not os.path.exists(str(path) + ".tmp.npz")


def test_cli_choices_come_from_the_registry(tmp_path):
    from blender_manikin import cli
    assert cli.FORMATS == tuple(formats.WRITERS) and set(cli.BLENDER_FORMATS) == {"blend", "fbx", "glb"}
    # a folder gives every file with a reader's extension (shared ones only when they look like
    # recordings: tests/test_json_recording.py), and nothing else
    own = [e for e in formats.input_extensions() if e not in formats.SHARED_EXTENSIONS]
    for e in own + [".txt", ".blend"]:
        (tmp_path / f"take{e}").write_bytes(b"")
    assert sorted(cli.expand_inputs([str(tmp_path)])) == sorted(str(tmp_path / f"take{e}") for e in own)
    assert cli.parse_formats("npz,json") == ("npz", "json")
