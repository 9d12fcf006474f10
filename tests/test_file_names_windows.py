"""Output names and files that Windows accepts, checked on every system: the names are made
so wherever the add-on or the command line runs (files move between systems), and the rules
that only hold on Windows (the 260-character path) take the platform as an argument."""
import builtins
import io
import json
import os

import numpy as np
import pytest

from blender_manikin.core import bvh, output_guard
from blender_manikin.core.convert import output_stems
from blender_manikin.core.file_names import file_stem, fold


@pytest.mark.parametrize("name, stem", [
    ("con.bsor", "con_"), ("aux.csv", "aux_"), ("NUL.json", "NUL_"), ("com1.trc", "com1_"),
    ("Lpt9.csv", "Lpt9_"), ("COM¹.csv", "COM¹_"), ("prn.take.csv", "prn_.take"), ("NUL .csv", "NUL_"),
    ("LPT9-take.csv", "LPT9-take"), ("console.csv", "console"), ("COM10.csv", "COM10"),
    ("a:b|c?.csv", "a_b_c_"), ("take. .csv", "take"), ("x\ty.csv", "x_y"),
])
def test_output_stems_are_names_windows_accepts(name, stem):
    path = os.path.abspath(os.path.join("takes", name))
    assert output_stems([path])[path] == stem


def test_windows_safe_rule():
    from blender_manikin.core.file_names import RESERVED, windows_safe
    assert {"CON", "PRN", "AUX", "NUL", "COM1", "COM9", "LPT1", "LPT9", "COM³", "LPT²"} <= RESERVED
    assert windows_safe("aux") == "aux_" and windows_safe("Aux.tar") == "Aux_.tar"
    assert windows_safe('a<b>c"d/e\\f') == "a_b_c_d_e_f"
    assert windows_safe("take...") == "take" and windows_safe(" . ", fallback="x") == "x"
    assert windows_safe("Übung 1") == "Übung 1"           # anything else as it was


def test_names_made_alike_by_the_rule_stay_apart():
    a, b = os.path.abspath("x/a:b.csv"), os.path.abspath("x/a_b.csv")
    stems = output_stems([a, b])
    assert stems[a] != stems[b] and fold(stems[a]) != fold(stems[b])
    assert all(stems[p].startswith("a_b-") for p in (a, b))


def test_file_stem_never_a_device_name():
    assert file_stem("CON") == "CON_"
    assert file_stem("nul") == "nul_"
    assert file_stem("Com3") == "Com3_"
    assert file_stem("CON_Walk") == "CON_Walk"


def test_bone_map_file_name_never_a_device_name():
    pytest.importorskip("bpy")
    from blender_manikin.operators.retarget import _file_name
    assert _file_name("con") == "con_"
    assert _file_name("aux.v2") == "aux_.v2"
    assert _file_name("my-map.v2") == "my-map.v2"


def test_long_names_cut_to_fit_windows_260_with_a_hash(tmp_path):
    from blender_manikin.core.convert import temp_tail
    from blender_manikin.core.file_names import MAX_PATH
    folder = os.path.join(str(tmp_path), "d" * 120)
    tail = temp_tail(["json", "npz"])
    paths = [os.path.abspath(os.path.join("in", "take_" + "x" * 190 + f"{i}.csv")) for i in range(2)]
    stems = output_stems(paths, folder, tail, windows=True)
    for p in paths:
        whole = os.path.join(folder, stems[p]) + "x" * tail
        assert len(whole) == MAX_PATH - 1                 # cut just to fit, its NUL included
        assert stems[p].startswith("take_xx")
    assert stems[paths[0]] != stems[paths[1]]             # the hash keeps two cut alike apart
    # off Windows, and where the name fits, nothing changes
    assert output_stems(paths, folder, tail, windows=False) == output_stems(paths)
    short = os.path.abspath("in/walk.csv")
    assert output_stems([short], folder, tail, windows=True)[short] == "walk"


def test_a_folder_too_deep_for_windows_is_named(tmp_path):
    from blender_manikin.core.convert import temp_tail
    from blender_manikin.core.file_names import fit_stem
    folder = os.path.join(str(tmp_path), "d" * 240)
    p = os.path.abspath("in/walk.csv")
    with pytest.raises(ValueError, match=r"output folder .*d{240}.*too long for Windows"):
        output_stems([p], folder, temp_tail(["json"]), windows=True)
    with pytest.raises(ValueError, match="too long for Windows"):
        fit_stem("walk", p, folder, 5, windows=True)
    assert output_stems([p], folder, temp_tail(["json"]), windows=False)[p] == "walk"


@pytest.fixture
def windows_line_ends(monkeypatch):
    """Text files opened to write as on Windows: ``newline=None`` writes ``\\r\\n``."""
    real = builtins.open

    def opened(file, mode="r", buffering=-1, encoding=None, errors=None, newline=None, closefd=True, opener=None):
        if any(m in mode for m in "wax") and "b" not in mode and newline is None:
            newline = "\r\n"
        return real(file, mode, buffering, encoding, errors, newline, closefd, opener)
    monkeypatch.setattr(builtins, "open", opened)
    monkeypatch.setattr(io, "open", opened)


def test_written_text_files_have_the_same_bytes_on_windows(tmp_path, windows_line_ends):
    from blender_manikin.core.export_json import write_json
    from blender_manikin.core.io_wide_csv import save_layout
    from blender_util import synthetic_result
    write_json(tmp_path / "take.json", synthetic_result(T=4, fps=30.0), source="take.csv")
    save_layout(tmp_path / "layout.json", {"columns": {"a": 1}})
    (tmp_path / "out.bvh").write_bytes(b"")
    output_guard.record([str(tmp_path / "out.bvh")])
    clip = bvh.BvhClip("t", ("root",), [-1], [[0, 0, 0]], [("Xposition", "Yposition", "Zposition")],
                       frame_time=1 / 30, motion=np.zeros((2, 3)))
    bvh.write_bvh(str(tmp_path / "clip.bvh"), clip)
    names = ["take.json", "layout.json", output_guard.RECORD, "clip.bvh"]
    for name in names:
        data = (tmp_path / name).read_bytes()
        assert b"\n" in data and b"\r" not in data, name
    json.loads((tmp_path / "take.json").read_text())
