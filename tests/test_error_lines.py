"""Errors on bad input name the file's line: a keypoint CSV's / TRC's frame whose time does not
advance, and the key at fault in a JSON side file (layout, device offsets, joint map)."""
import json

import pytest

from blender_manikin.core import joint_maps as jmod
from blender_manikin.core.device_offsets import load_offsets
from blender_manikin.core.io_keypoints import read_keypoint_people, read_keypoints
from blender_manikin.core.io_wide_csv import load_layout
from blender_manikin.core.recording import RecordingError, json_key_line

from fixtures_keypoints import hinge_motion, set_csv_cells, write_layout_csv, write_trc


@pytest.fixture(scope="module")
def motion():
    return hinge_motion(frames=60, seed=0)


def _time_back(lines, k):
    """Row ``k`` of a table's text lines with its time cell set to the previous row's."""
    sep = "\t" if "\t" in lines[k] else ","
    ti = 1 if sep == "\t" else 0
    prev, row = lines[k - 1].split(sep), lines[k].split(sep)
    row[ti] = prev[ti]
    lines[k] = sep.join(row)


def test_keypoint_csv_time_not_advancing_names_its_line(tmp_path, motion):
    body, pos, world = motion
    path = tmp_path / "kp.csv"
    write_layout_csv(path, "coco17", body, pos, world)
    lines = path.read_text().splitlines()
    lines.insert(1, "# a comment line")          # skipped rows still count as lines
    _time_back(lines, 21)                         # line 22: frame 19 (the header, the comment, frames 0..18 before)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=r"kp.csv, line 22: time .* s of frame 19 is not after the previous "
                                             r"frame's .* s") as e:
        read_keypoints(path)
    assert e.value.line == 22


def test_keypoint_csv_empty_time_cell_names_its_line(tmp_path, motion):
    body, pos, world = motion
    path = tmp_path / "gap.csv"
    write_layout_csv(path, "coco17", body, pos, world)
    set_csv_cells(path, {(31, 0): ""})
    with pytest.raises(RecordingError, match=r"gap.csv, line 32: time nan s of frame 30 is not after"):
        read_keypoints(path)


def test_keypoint_csv_frame_column_names_its_line(tmp_path, motion):
    """A frame-number column read with a rate: a frame number that goes back names its line, also
    through read_keypoint_people (one person)."""
    body, pos, world = motion
    path = tmp_path / "frames.csv"
    write_layout_csv(path, "coco17", body, pos, world)
    n = len(path.read_text().splitlines())
    # frame numbers for times; line 11 (index 10): frame 9 written as 3
    set_csv_cells(path, {(0, 0): "frame", **{(k, 0): str(k - 1 if k != 10 else 3) for k in range(1, n)}})
    for read in (read_keypoints, read_keypoint_people):
        with pytest.raises(RecordingError, match=r"frames.csv, line 11: time .* s of frame 9 is not after"):
            read(path, rate=30)


def test_trc_time_not_advancing_names_its_line(tmp_path, motion):
    body, pos, world = motion
    path = tmp_path / "back.trc"
    write_trc(path, body, pos, world)
    lines = path.read_text().splitlines()
    first = next(k for k in range(5, len(lines)) if lines[k].strip())     # the first data row
    _time_back(lines, first + 12)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=rf"back.trc, line {first + 13}: time .* s of frame 12 is not after"):
        read_keypoints(path)


def test_json_key_line():
    text = ('{"format": "wide_csv",\n'
            '  "devices": {\n'
            '    "head": {"pos": ["a", "b", "c"]},\n'
            '    "right_hand": {\n'
            '      "pos": ["d", "e", "f"],\n'
            '      "rot": [0, 0, 0, 0]\n'
            '    }\n'
            '  },\n'
            '  "rot": "not the one",\n'
            '  "list": [{"rot": 1}, {"a\\"b": "x\\ny",\n'
            '  "rot": 2}]\n'
            '}\n')
    assert json_key_line(text, ("devices", "right_hand", "rot")) == 6
    assert json_key_line(text, ("rot",)) == 9
    assert json_key_line(text, ("devices", "head", "rot")) == 3      # missing: its device's line
    assert json_key_line(text, ("list", 1, "rot")) == 11
    assert json_key_line(text, ("list", 1, 'a"b')) == 10
    assert json_key_line(text, ("nope",)) is None


def test_json_key_line_array_elements():
    """An array index in the path names the line its element starts on (pretty-printed: each its
    own line; one line: that line); past the end, the array's key's line."""
    doc = {"parents": [["a", "b"], ["c", "d"], ["e", 3]], "pos": [0.5, "x", 1], "deep": [[1, [2, {"k": 4}]]]}
    text = json.dumps(doc, indent=2)
    lines = text.splitlines()
    par = next(k for k, t in enumerate(lines, 1) if '"parents":' in t)
    assert json_key_line(text, ("parents", 0)) == par + 1
    assert json_key_line(text, ("parents", 2)) == par + 9            # each pair is 4 lines: [, a, b, ]
    assert json_key_line(text, ("parents", 2, 1)) == par + 11
    assert json_key_line(text, ("parents", 7)) == par                # no such element: the key's line
    pos = next(k for k, t in enumerate(lines, 1) if '"pos":' in t)
    assert json_key_line(text, ("pos", 1)) == pos + 2
    assert lines[json_key_line(text, ("deep", 0, 1, 1, "k")) - 1].strip() == '"k": 4'
    one = json.dumps(doc)
    assert all(json_key_line(one, k) == 1 for k in (("parents", 2), ("pos", 1), ("deep", 0, 1, 1, "k")))
    assert json_key_line('[\n 1,\n "a,]\\"[",\n 3\n]', (2,)) == 4    # commas and brackets in strings


def test_array_element_errors_name_the_element_line(tmp_path):
    from test_joint_map_files import _lafan1_file_dict
    off = tmp_path / "offsets.json"
    off.write_text(json.dumps({"devices": {"head": {"pos": [0, 0, 0], "rot": [1, 0, 0, "x"]}}}, indent=2))
    want = next(k for k, t in enumerate(off.read_text().splitlines(), 1) if '"x"' in t)
    with pytest.raises(RecordingError, match=rf"offsets.json, line {want}: head: pos/rot must be lists of numbers"):
        load_offsets(off)
    d = _lafan1_file_dict()
    d["parents"] = [["Hips", "Spine"], ["Head", 3]]
    f = tmp_path / "map.json"
    f.write_text(json.dumps(d, indent=2))
    lines = f.read_text().splitlines()
    par = next(k for k, t in enumerate(lines) if '"parents":' in t)
    want = next(k for k in range(par, len(lines)) if '"Head",' in lines[k])   # the bad pair's "[" is the line before
    with pytest.raises(ValueError, match=rf"map.json, line {want}: parents must be a list"):
        jmod.load_joint_map(f)


def test_layout_content_error_names_its_line(tmp_path):
    bad = tmp_path / "layout.json"
    bad.write_text(json.dumps({"format": "wide_csv",
                               "devices": {"head": {"pos": ["x", "y", "z"], "rot": None},
                                           "elbow": {"pos": ["a", "b", "c"]}},
                               "time": {"column": "t", "unit": "s"}}, indent=2))
    want = next(k for k, t in enumerate(bad.read_text().splitlines(), 1) if '"elbow":' in t)
    with pytest.raises(RecordingError, match=rf"layout.json, line {want}: layout file: unknown device 'elbow'"):
        load_layout(bad)


def test_offsets_content_error_names_its_line(tmp_path):
    bad = tmp_path / "offsets.json"
    bad.write_text('{\n  "devices": {\n    "head": {"pos": [0, 0, 0]},\n    "right_hand": {\n'
                   '      "pos": [0, 0, 0],\n      "rot": [0, 0, 0, 0]\n    }\n  }\n}\n')
    with pytest.raises(RecordingError, match=r"offsets.json, line 6: right_hand: 'rot' must be a non-zero "
                                             r"quaternion"):
        load_offsets(bad)
    (tmp_path / "bare.json").write_text('{"head": {"pos": [0, 0, 0]},\n "tail": {}}')     # the bare form
    with pytest.raises(RecordingError, match=r"bare.json, line 2: unknown device 'tail'"):
        load_offsets(tmp_path / "bare.json")


def test_joint_map_content_error_names_its_line(tmp_path):
    from test_joint_map_files import _lafan1_file_dict
    d = _lafan1_file_dict()
    d["orientations"]["head"]["primary"] = "up"
    f = tmp_path / "map.json"
    f.write_text(json.dumps(d, indent=2))
    lines = f.read_text().splitlines()
    start = next(k for k, t in enumerate(lines) if '"orientations":' in t)
    head = next(k for k in range(start, len(lines)) if '"head":' in lines[k])
    want = next(k for k in range(head, len(lines)) if '"primary":' in lines[k]) + 1
    with pytest.raises(ValueError, match=rf"map.json, line {want}: orientations.head.primary: bad axis") as e:
        jmod.load_joint_map(f)
    assert str(e.value).startswith(f"{f}, line {want}: ")
