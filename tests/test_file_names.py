"""core/file_names.py: output names from users' names, apart on case-insensitive disks."""
import unicodedata

from blender_manikin.core.file_names import file_stem, fold, unique_stems


def test_fold_is_how_windows_and_macos_compare_names():
    assert fold("Take") == fold("take") == fold("TAKE")
    assert fold(unicodedata.normalize("NFD", "Übung")) == fold("übung")
    assert fold("Take") != fold("Take2")


def test_file_stem_keeps_letters_of_any_script():
    assert file_stem("Übung 1") == "Übung_1"
    assert file_stem("テイク_01") == "テイク_01"
    assert file_stem(unicodedata.normalize("NFD", "café")) == "café"
    assert file_stem("a/b:c*d?e\"f<g>h|i#j%k&l'm") == "a_b_c_d_e_f_g_h_i_j_k_l_m"
    assert file_stem("Walk.001") == "Walk_001"          # as bpy.path.clean_name for ASCII
    assert file_stem("...", fallback="x") == "x"


def test_unique_stems_suffixes_later_clashes_only():
    assert unique_stems(["Walk", "walk", "Run", "WALK", "walk_2"]) == ["Walk", "walk_2", "Run", "WALK_3", "walk_2_2"]
    got = unique_stems(["Walk", "walk", "Run", "WALK", "walk_2"])
    assert len({fold(s) for s in got}) == len(got)
