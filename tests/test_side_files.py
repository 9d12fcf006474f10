"""The small files beside a recording, as Windows editors save them: layout, device offsets,
bone map, keypoint mapping and training-source JSON files, and convert's manifest lists, with a
UTF-8 BOM (Notepad, PowerShell's ``Set-Content -Encoding UTF8``) or in UTF-16 (PowerShell's
``Out-File``) are read (they failed: "Unexpected UTF-8 BOM", a bare UnicodeDecodeError naming
no file, a manifest's first line taken as a path); a byte that is not UTF-8 is named with the
file and its line."""
import json

import pytest

from blender_manikin.core import bone_maps, convert, device_offsets, io_wide_csv
from blender_manikin.core.recording import RecordingError

ENCODINGS = {"bom": lambda t: b"\xef\xbb\xbf" + t.encode("utf-8"), "utf16": lambda t: t.encode("utf-16")}
LAYOUT = {"format": "wide_csv", "time": {"column": "t", "unit": "s"},
          "devices": {"head": {"pos": ["hx", "hy", "hz"], "rot": ["qw", "qx", "qy", "qz"]}}}


def _write(path, text, enc):
    path.write_bytes(ENCODINGS[enc](text))
    return path


@pytest.mark.parametrize("enc", sorted(ENCODINGS))
def test_json_side_files_with_a_bom_or_in_utf16(tmp_path, enc):
    preset = device_offsets.get_preset("openxr_generic")
    device_offsets.save_offsets(tmp_path / "o.json", preset)
    got = device_offsets.load_offsets(_write(tmp_path / "o2.json", (tmp_path / "o.json").read_text("utf-8"), enc))
    assert got == device_offsets.load_offsets(tmp_path / "o.json")
    assert io_wide_csv.load_layout(_write(tmp_path / "l.json", json.dumps(LAYOUT), enc))["devices"] == LAYOUT["devices"]
    bmap = bone_maps.validate_bone_map({"name": "Übung", "bones": {"pelvis": "Hüfte"}})
    bone_maps.save_bone_map(tmp_path / "b.json", bmap)
    again = bone_maps.load_bone_map(_write(tmp_path / "b2.json", (tmp_path / "b.json").read_text("utf-8"), enc))
    assert again == bone_maps.load_bone_map(tmp_path / "b.json")


@pytest.mark.parametrize("enc", sorted(ENCODINGS))
def test_manifest_list_with_a_bom(tmp_path, enc):
    (tmp_path / "a.csv").write_text("x")
    lst = _write(tmp_path / "takes.txt", "# my takes\r\na.csv\r\n", enc)
    assert convert._read_manifest_file(str(lst)) == [str(tmp_path / "a.csv")]


@pytest.mark.parametrize("enc", sorted(ENCODINGS))
def test_training_sources_with_a_bom(tmp_path, enc):
    from blender_manikin.training import dataset
    src = _write(tmp_path / "sources.json", json.dumps([{"path": "walk.bvh", "joint_map": "cmu"}]), enc)
    assert [s.joint_map for s in dataset.load_sources(str(src))] == ["cmu"]


def test_a_bad_byte_names_the_file_and_line(tmp_path):
    text = json.dumps(LAYOUT, indent=1).replace('"t"', '"t \u00b5s"')
    (tmp_path / "lay.json").write_bytes(text.encode("latin-1"))
    line = text[:text.index("\u00b5")].count("\n") + 1
    for load in (io_wide_csv.load_layout, device_offsets.load_offsets, bone_maps.load_bone_map):
        with pytest.raises(RecordingError, match=rf"lay.json, line {line}: not UTF-8 text \(byte 0xb5\)"):
            load(tmp_path / "lay.json")
