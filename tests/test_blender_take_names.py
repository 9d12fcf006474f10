"""Export Each Take with takes named as users name them: two takes whose names differ only in
case, or only in a letter outside ASCII, each get their own FBX (they were written to one file,
the second over the first: ``Übung 1`` and ``Äbung 1`` both ``_bung_1``; ``Walk`` and ``walk``
one file on Windows and macOS)."""
import os

import pytest

bpy = pytest.importorskip("bpy")

from blender_manikin.blender import fbx_presets, retarget_apply, writer  # noqa: E402
from blender_manikin.core.file_names import fold  # noqa: E402

from blender_util import mixamo_style_character, synthetic_result  # noqa: E402


@pytest.mark.parametrize("names", [("Übung 1", "Äbung 1"), ("Walk", "walk"), ("テイク_01", "テイク.01")])
def test_takes_named_alike_get_a_file_each(addon, tmp_path, names):
    char = mixamo_style_character(stature=1.9)
    for k, name in enumerate(names):
        res = synthetic_result(T=12 + 4 * k, fps=24.0, seed=k, stature=1.75)
        src = writer.write_result(res, writer.WriteOptions(frame_start=1, armature_name=f"MANIKIN_src{k}")).armature
        retarget_apply.retarget_onto(src, char, "mixamo", None, "scaled", False)
        char.animation_data.action.name = f"MANIKIN_retarget_{name}"
    actions = [bpy.data.actions[f"MANIKIN_retarget_{n}"] for n in names]
    paths = fbx_presets.export_fbx_takes(str(tmp_path / "takes"), char, "unity", actions=actions)
    assert len({fold(p) for p in paths}) == 2, paths
    assert all(os.path.isfile(p) for p in paths)
    if names[0][0] in "ÜテW":
        assert os.path.basename(paths[0]).startswith(f"{char.name}_{names[0][:3]}")   # letters kept
