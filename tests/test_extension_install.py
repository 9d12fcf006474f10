"""The extension zip: build, Blender's validator, and a real install into a fresh Blender.

The install runs in a SUBPROCESS that cannot see this environment's onnxruntime: the interpreter
is started with ``-I -S`` (no site-packages at all) and gets a path holding only symlinks to
bpy and numpy.  Blender's own installer (``bpy.ops.extensions.package_install_files``) puts the
zip into a user directory under ``tmp_path`` (BLENDER_USER_* variables), installs the bundled
wheel, and the add-on is enabled; the test then checks that the onnxruntime that got imported
is the one from the extension's site-packages, that it runs a model, that the add-on
registered, and solves the bundled example end to end with the shipped model.  With a real
``blender`` binary the same zip is installed by ``blender --command extension install-file``.
"""
from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import textwrap
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import build_addon  # noqa: E402

pytestmark = pytest.mark.skipif(importlib.util.find_spec("bpy") is None, reason="bpy is not installed")

PKG = ROOT / "blender_manikin"
PLATFORM = "linux-x64"
MODELS = sorted((PKG / "models").glob("*.onnx"))
EXAMPLE = ROOT / "examples" / "example_recording.csv"
EXT_MODULE = "bl_ext.user_default.blender_manikin"


def _wheel_cache() -> Path:
    return Path(os.environ.get("BLENDER_MANIKIN_WHEEL_CACHE",
                               Path.home() / ".cache" / "blender_manikin" / "wheels"))


def _tiny_onnx_model() -> bytes:
    """y = x * x on a float[3], as ONNX protobuf bytes written by hand (no onnx package needed)."""
    def varint(n: int) -> bytes:
        out = bytearray()
        while True:
            b = n & 0x7F
            n >>= 7
            out.append(b | (0x80 if n else 0))
            if not n:
                return bytes(out)

    def field(num: int, value) -> bytes:
        if isinstance(value, int):
            return varint(num << 3) + varint(value)
        data = value.encode() if isinstance(value, str) else value
        return varint(num << 3 | 2) + varint(len(data)) + data

    def value_info(name: str) -> bytes:
        shape = field(1, field(1, 3))                         # TensorShapeProto.dim{dim_value: 3}
        tensor = field(1, 1) + field(2, shape)                # elem_type FLOAT, shape
        return field(1, name) + field(2, field(1, tensor))    # name, TypeProto.tensor_type

    node = field(1, "x") + field(1, "x") + field(2, "y") + field(4, "Mul")
    graph = field(1, node) + field(2, "tiny") + field(11, value_info("x")) + field(12, value_info("y"))
    return field(1, 7) + field(8, field(1, "") + field(2, 13)) + field(7, graph)


# The script that runs inside the isolated interpreter.
# argv: report.json zip tiny.onnx solve(0/1) example out_dir take.xror
CHILD = textwrap.dedent(r'''
    import importlib, importlib.util, json, os, sys, traceback
    report_path, zip_path, tiny_model, solve, example, out_dir, xror = sys.argv[1:8]
    report = {"errors": {}}

    def step(name):
        def wrap(fn):
            try:
                report[name] = fn()
            except BaseException as ex:
                report["errors"][name] = "".join(traceback.format_exception(ex))
            return fn
        return wrap

    try:
        report["ort_visible_before_install"] = importlib.util.find_spec("onnxruntime") is not None
        report["xror_codecs_visible_before_install"] = [importlib.util.find_spec(m) is not None
                                                        for m in ("bson", "fpzip")]
        report["sys_path"] = list(sys.path)
        import bpy, addon_utils
        report["blender"] = bpy.app.version_string
        report["extensions_dir"] = bpy.utils.user_resource("EXTENSIONS")
        report["site_packages"] = os.path.join(
            bpy.utils.user_resource("EXTENSIONS", path=".local"),
            "lib", "python{}.{}".format(*sys.version_info[:2]), "site-packages")

        @step("install")
        def _():
            return sorted(bpy.ops.extensions.package_install_files(
                filepath=zip_path, repo="user_default", enable_on_install=True))

        @step("enabled")
        def _():
            return list(addon_utils.check("''' + EXT_MODULE + r'''"))

        @step("onnxruntime")
        def _():
            import onnxruntime
            import numpy as np
            sess = onnxruntime.InferenceSession(tiny_model, providers=["CPUExecutionProvider"])
            y = sess.run(None, {"x": np.array([1.0, 2.0, 3.0], dtype=np.float32)})[0]
            capi = os.path.join(os.path.dirname(onnxruntime.__file__), "capi")
            return {"file": onnxruntime.__file__, "version": onnxruntime.__version__, "y": y.tolist(),
                    "numpy": np.__version__, "numpy_file": np.__file__,
                    "dist_infos": sorted(n for n in os.listdir(report["site_packages"])
                                         if n.startswith("onnxruntime-") and n.endswith(".dist-info")),
                    "extension_modules": sorted(n for n in os.listdir(capi) if n.endswith((".so", ".pyd")))}

        @step("loader")
        def _():
            loader = importlib.import_module("''' + EXT_MODULE + r'''.core.onnx_runtime_loader")
            return {"kind": loader.install_kind(), "file": loader.load_onnxruntime().__file__}

        @step("registered")
        def _():
            return {"ops": sorted(dir(bpy.ops.manikin)),
                    "scene_props": sorted(p.identifier for p in bpy.types.Scene.bl_rna.properties
                                          if "manikin" in p.identifier)}

        @step("xror")
        def _():       # the .xror reader, with the bson and fpzip the zip bundles
            formats = importlib.import_module("''' + EXT_MODULE + r'''.core.formats")
            rec = formats.load_recording(xror)
            import bson, fpzip
            return {"devices": sorted(rec.streams), "samples": len(rec.streams["head"].time),
                    "bson": bson.__file__, "fpzip": fpzip.__file__}

        @step("unshipped_modules_loaded")
        def _():
            return sorted({m.split(".")[0] for m in sys.modules} &
                          {"sympy", "mpmath", "google", "coloredlogs", "humanfriendly", "flatbuffers", "packaging"})

        if solve == "1":
            @step("solve")
            def _():
                settings = bpy.context.scene.manikin
                settings.source = "FILE"
                settings.filepath = example
                actions_before = len(bpy.data.actions)
                result = sorted(bpy.ops.manikin.solve_full_body("EXEC_DEFAULT"))
                keyed = 0
                for action in bpy.data.actions:
                    curves = getattr(action, "fcurves", None)
                    if curves is None:  # Blender 5: layered actions only
                        curves = [c for layer in action.layers for strip in layer.strips
                                  for bag in strip.channelbags for c in bag.fcurves]
                    keyed = max(keyed, max((len(c.keyframe_points) for c in curves), default=0))
                return {"result": result, "actions": len(bpy.data.actions) - actions_before,
                        "max_keyframes": keyed, "last_report": settings.last_report}

        @step("disable")
        def _():
            def reraise(ex):
                raise ex
            addon_utils.disable("''' + EXT_MODULE + r'''", default_set=True, handle_error=reraise)
            return list(addon_utils.check("''' + EXT_MODULE + r'''"))

        if solve == "1":
            # The batch CLI from the installed copy (it resets to a factory scene, so it runs last).
            @step("cli")
            def _():
                cli = importlib.import_module("''' + EXT_MODULE + r'''.cli")
                code = cli.main(["solve", example, "--out", out_dir, "--format", "json,bvh"])
                return {"exit": code, "outputs": sorted(
                    (name, os.path.getsize(os.path.join(out_dir, name))) for name in os.listdir(out_dir))}
    except BaseException as ex:
        report["errors"]["fatal"] = "".join(traceback.format_exception(ex))
    with open(report_path, "w") as fh:
        json.dump(report, fh, indent=1)
''')


def _xror_bytes(n=90) -> bytes:
    """A small XROR document: head and hands standing still for ``n`` frames at 90 Hz."""
    import numpy as np
    from fixtures_recordings import xror_bytes
    pose = np.tile(np.array([[0, 1.6, 0, 0, 0, 0, 1], [-0.3, 1.2, 0.3, 0, 0, 0, 1], [0.3, 1.2, 0.3, 0, 0, 0, 1]],
                            np.float64), (n, 1, 1))
    return xror_bytes(np.arange(n) / 90.0, pose, app="test")


def _isolated_site(dest: Path) -> Path:
    """A directory holding only bpy and numpy (symlinks) from this environment."""
    dest.mkdir(parents=True, exist_ok=True)
    for name in ("bpy", "numpy"):
        spec = importlib.util.find_spec(name)
        assert spec is not None and spec.submodule_search_locations, f"{name} not installed"
        src = Path(list(spec.submodule_search_locations)[0])
        (dest / name).symlink_to(src, target_is_directory=True)
        libs = src.parent / f"{name}.libs"
        if libs.is_dir():
            (dest / libs.name).symlink_to(libs, target_is_directory=True)
    return dest


@pytest.fixture(scope="module")
def build_dir(tmp_path_factory) -> dict:
    """Build the linux-x64 zip of the repository's package."""
    assert MODELS, "no shipped model in blender_manikin/models"
    base = tmp_path_factory.mktemp("extension")
    (zip_path,) = build_addon.build([PLATFORM], base / "dist", _wheel_cache(), quiet=True)
    return {"base": base, "zip": zip_path}


@pytest.fixture(scope="module")
def installed(build_dir) -> dict:
    base: Path = build_dir["base"]
    home = base / "home"
    for d in ("resources", "config", "scripts"):
        (home / d).mkdir(parents=True)
    site = _isolated_site(base / "isolated_site")
    tiny = base / "tiny.onnx"
    tiny.write_bytes(_tiny_onnx_model())
    script = base / "child.py"
    script.write_text(CHILD)
    report_path = base / "report.json"
    xror = base / "take.xror"
    xror.write_bytes(_xror_bytes())
    env = {
        "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
        "HOME": str(home),
        "LANG": "C.UTF-8",
        "BLENDER_USER_RESOURCES": str(home / "resources"),
        "BLENDER_USER_CONFIG": str(home / "config"),
        "BLENDER_USER_SCRIPTS": str(home / "scripts"),
    }
    solve = "1"
    bootstrap = (f"import sys; sys.path.insert(0, {str(site)!r}); "
                 f"sys.argv = [{str(script)!r}] + sys.argv[1:]; "
                 f"exec(compile(open({str(script)!r}).read(), {str(script)!r}, 'exec'))")
    cmd = [sys.executable, "-I", "-S", "-c", bootstrap, str(report_path), str(build_dir["zip"]), str(tiny),
           solve, str(EXAMPLE), str(base / "out"), str(xror)]
    proc = subprocess.run(cmd, env=env, cwd=base, capture_output=True, text=True, timeout=600)
    assert report_path.exists(), f"child crashed (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}"
    report = json.loads(report_path.read_text())
    report["_log"] = proc.stdout + proc.stderr
    assert "fatal" not in report["errors"], report["errors"]["fatal"] + report["_log"]
    return report


def _step(report: dict, name: str):
    assert name not in report["errors"], f"{name} failed in Blender:\n{report['errors'][name]}\n{report['_log']}"
    return report[name]


# ----------------------------------------------------------------------------- the zip

def test_zip_layout_and_manifest(build_dir):
    with zipfile.ZipFile(build_dir["zip"]) as zf:
        names = zf.namelist()
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode())
    assert build_dir["zip"].name == f"blender_manikin-{build_addon.read_version()}-linux_x64.zip"
    assert manifest["schema_version"] == "1.0.0"
    assert manifest["id"] == "blender_manikin"
    assert manifest["version"] == build_addon.read_version()
    assert manifest["blender_version_min"] == "4.2.0"
    assert manifest["license"] == ["SPDX:MIT"]
    assert "CC BY-NC" in manifest["tagline"]
    assert manifest["permissions"] == {"files": "Read VR tracker recordings and write animation files"}
    assert manifest["platforms"] == [PLATFORM]
    wheels = [w.removeprefix("./") for w in manifest["wheels"]]
    assert sorted(wheels) == sorted(n for n in names if n.startswith("wheels/"))
    # One zip per platform serves every supported Blender: an onnxruntime wheel per Python version.
    for py, version in build_addon.read_onnxruntime_pins().items():
        tag = "cp{}{}".format(*py)
        assert sum(w.startswith(f"wheels/onnxruntime-{version}-{tag}-{tag}-") for w in wheels) == 1, (py, wheels)
    assert build_addon.PYTHON_VERSIONS == ((3, 11), (3, 13))
    assert not any("numpy" in w for w in wheels), "Blender ships numpy; bundling one breaks it"
    assert "__init__.py" in names and "core/onnx_runtime_loader.py" in names and "core/pipeline.py" in names
    # the keypoint solve (the panel's Keypoints source) ships, with the HybrIK IK it runs
    for used in ("core/keypoint_solve.py", "core/keypoint_layouts.py", "core/io_keypoints.py", "core/hybrik.py"):
        assert used in names, used
    # mocap preparation and evaluation code is not shipped: the add-on never imports it
    for unused in ("core/bvh.py", "core/asf_amc.py", "core/joint_maps.py", "core/metrics.py",
                   "core/baselines.py"):
        assert unused not in names, unused
    for n in names:
        assert "__pycache__" not in n and not n.endswith((".pyc", ".pt"))
        assert not n.startswith(("tests/", "training/"))
    for model in MODELS:
        assert f"models/{model.name}" in names


def test_version_comes_from_one_place(tmp_path):
    assert f'__version__ = "{build_addon.read_version()}"' in (PKG / "core" / "version.py").read_text()
    import blender_manikin
    assert blender_manikin.__version__ == build_addon.read_version()
    assert tuple(blender_manikin.bl_info["version"]) == tuple(int(x) for x in build_addon.read_version().split("."))
    pkg = tmp_path / "blender_manikin"
    (pkg / "core").mkdir(parents=True)
    (pkg / "core" / "version.py").write_text('__version__ = "1.2.3"\n')
    (pkg / "__init__.py").write_text('bl_info = {"name": "x", "version": (1, 2, 4)}\n')
    with pytest.raises(build_addon.BuildError, match="disagrees"):
        build_addon.read_version(pkg)


def test_validator_rejects_a_bad_manifest(build_dir, tmp_path):
    """The build's validation really is Blender's: a manifest Blender refuses fails the build."""
    src = build_dir["zip"]
    bad = tmp_path / src.name
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(bad, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename == "blender_manifest.toml":
                data = data.replace(b'[permissions]\n', b'[permissions]\nteleport = "Beam animators around."\n')
            zout.writestr(item, data)
    with pytest.raises(build_addon.BuildError, match="teleport"):
        build_addon.validate_zip(bad, PLATFORM, build_addon.find_blender_ext())
    with pytest.raises(build_addon.BuildError, match="not for"):
        build_addon.validate_zip(src, "windows-x64", build_addon.find_blender_ext())


def test_build_refuses_imports_that_break_inside_blender(tmp_path):
    pkg = tmp_path / "blender_manikin"
    (pkg / "core").mkdir(parents=True)
    (pkg / "__init__.py").write_text('__version__ = "0.0.1"\nfrom . import core\n')
    (pkg / "core" / "__init__.py").write_text("")
    (pkg / "core" / "ok.py").write_text("from . import other\nfrom ..core import ok\nimport numpy\n")
    (pkg / "core" / "bad.py").write_text("from blender_manikin.core import ok\nfrom ..training import export\n"
                                         "import bpy\nfrom .. import panels\n")
    (pkg / "panels.py").write_text("from .core import bad, ok\n")
    files, skipped = build_addon.package_files(pkg)
    with pytest.raises(build_addon.BuildError) as info:
        build_addon.check_imports(files)
    text = str(info.value)
    assert "core/bad.py:1: import blender_manikin.core (absolute" in text
    assert "core/bad.py:2: imports training, which is not shipped" in text
    assert "core/bad.py:2: core/ imports training, outside core/" in text
    assert "core/bad.py:3: core/ imports Blender's modules" in text
    assert "core/bad.py:4: core/ imports panels, outside core/" in text
    assert "ok.py" not in text
    # a core module nothing outside core/ imports is left out
    (pkg / "core" / "lonely.py").write_text("import numpy\n")
    files, skipped = build_addon.package_files(pkg)
    names = [rel for _, rel in files]
    assert "core/lonely.py" not in names and "core/ok.py" in names and "core/bad.py" in names
    assert "core/lonely.py (not used by the add-on)" in skipped


def test_onnxruntime_pins_live_in_one_place(tmp_path):
    """requirements-onnxruntime.txt holds one pin per Python; any other requirements file pinning
    onnxruntime itself, a missing Python, or a loader that quotes another version stops the build."""
    pins = build_addon.read_onnxruntime_pins()
    assert set(pins) == set(build_addon.PYTHON_VERSIONS)
    from blender_manikin.core import onnx_runtime_loader as loader
    assert loader.BUNDLED_ONNXRUNTIME == {"{}.{}".format(*k): v for k, v in pins.items()}
    for name in ("requirements-test.txt", "requirements-bpy42.txt", "requirements-bpy52.txt"):
        assert "-r requirements-onnxruntime.txt" in (ROOT / name).read_text().splitlines(), name

    def tree(pin_text, other_text="", loader_text=None):
        d = tmp_path / f"t{len(list(tmp_path.iterdir()))}"
        (d / "blender_manikin" / "core").mkdir(parents=True)
        (d / "requirements-onnxruntime.txt").write_text(pin_text)
        (d / "requirements-x.txt").write_text(other_text)
        (d / "blender_manikin" / "core" / "onnx_runtime_loader.py").write_text(
            loader_text or 'BUNDLED_ONNXRUNTIME = {"3.11": "1.20.1", "3.13": "1.20.1"}\n')
        return d / "requirements-onnxruntime.txt"

    good = 'onnxruntime==1.20.1; python_version == "3.11"\nonnxruntime==1.20.1 ; python_version=="3.13"  # ok\n'
    assert build_addon.read_onnxruntime_pins(tree(good)) == {(3, 11): "1.20.1", (3, 13): "1.20.1"}
    with pytest.raises(build_addon.BuildError, match="requirements-x.txt pins onnxruntime itself"):
        build_addon.read_onnxruntime_pins(tree(good, "onnxruntime==1.22.0\n"))
    with pytest.raises(build_addon.BuildError, match="no onnxruntime pin for Python 3.13"):
        build_addon.read_onnxruntime_pins(tree('onnxruntime==1.20.1; python_version == "3.11"\n'))
    with pytest.raises(build_addon.BuildError, match="disagrees"):
        newer = 'BUNDLED_ONNXRUNTIME = {"3.11": "1.20.1", "3.13": "1.22.0"}\n'
        build_addon.read_onnxruntime_pins(tree(good, loader_text=newer))
    with pytest.raises(build_addon.BuildError, match="cannot read"):
        build_addon.read_onnxruntime_pins(tree("onnxruntime>=1.20\n"))


def test_wheels_are_matched_to_each_python():
    fits = build_addon._wheel_fits_python
    assert fits("onnxruntime-1.20.1-cp313-cp313-win_amd64.whl", (3, 13))
    assert not fits("onnxruntime-1.20.1-cp313-cp313-win_amd64.whl", (3, 11))
    assert not fits("onnxruntime-1.20.1-cp311-cp311-win_amd64.whl", (3, 13))
    assert fits("flatbuffers-25.1.24-py2.py3-none-any.whl", (3, 13))
    assert fits("cryptography-44.0.0-cp39-abi3-manylinux_2_28_x86_64.whl", (3, 11))
    assert not fits("cryptography-44.0.0-cp314-abi3-manylinux_2_28_x86_64.whl", (3, 13))


def test_windows_binaries_needing_msvcp140_14_40_are_refused(tmp_path):
    """onnxruntime >= 1.21 (constexpr std::mutex, no _Mtx_init_in_situ import) cannot load in
    Blender 4.2-5.0 on Windows; the build must refuse such a wheel."""
    def fake_wheel(name, dll_imports):
        path = tmp_path / name
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("onnxruntime/capi/onnxruntime.dll", b"MZ\x00MSVCP140.dll\x00" + dll_imports)
        return path

    old_style = fake_wheel("onnxruntime-1.20.1-cp311-cp311-win_amd64.whl",
                           b"\x00\x00_Mtx_init_in_situ\x00\x00\x00_Mtx_lock\x00")
    assert "fine" in build_addon.check_windows_msvc_runtime(old_style)
    new_style = fake_wheel("onnxruntime-1.21.0-cp311-cp311-win_amd64.whl", b"\x00\x00_Mtx_lock\x00")
    with pytest.raises(build_addon.BuildError, match="14.40"):
        build_addon.check_windows_msvc_runtime(new_style)


# ----------------------------------------------------------------------------- the install

def test_isolated_interpreter_cannot_see_the_test_onnxruntime(installed):
    assert installed["ort_visible_before_install"] is False, installed["sys_path"]


def test_installed_with_blenders_installer(installed):
    assert _step(installed, "install") == ["FINISHED"]
    assert _step(installed, "enabled") == [True, True]


def test_onnxruntime_comes_from_the_extension_wheels(installed):
    ort = _step(installed, "onnxruntime")
    site_packages = Path(installed["site_packages"]).resolve()
    assert Path(ort["file"]).resolve().is_relative_to(site_packages), (ort["file"], site_packages)
    assert ort["version"] == build_addon.read_onnxruntime_pin(sys.version_info[:2])
    # Blender installed only the wheel for its own Python.
    assert ort["dist_infos"] == [f"onnxruntime-{ort['version']}.dist-info"], ort["dist_infos"]
    tag = "cpython-{}{}".format(*sys.version_info[:2])
    assert any(tag in name for name in ort["extension_modules"]), \
        ("the onnxruntime extension module is not built for this Python", ort["extension_modules"])
    assert ort["y"] == [1.0, 4.0, 9.0]
    loader = _step(installed, "loader")
    assert loader["kind"] == "extension"
    assert Path(loader["file"]).resolve().is_relative_to(site_packages)
    assert _step(installed, "unshipped_modules_loaded") == []


def test_xror_reads_inside_blender_with_the_bundled_codecs(installed):
    assert installed["xror_codecs_visible_before_install"] == [False, False], installed["sys_path"]
    got = _step(installed, "xror")
    site_packages = Path(installed["site_packages"]).resolve()
    assert Path(got["bson"]).resolve().is_relative_to(site_packages), got
    assert Path(got["fpzip"]).resolve().is_relative_to(site_packages), got
    assert got["devices"] == ["head", "left_hand", "right_hand"] and got["samples"] == 90, got


def test_addon_registered(installed):
    reg = _step(installed, "registered")
    assert reg["ops"] or reg["scene_props"], "the add-on registered no bpy.ops.manikin operator and no scene property"
    assert _step(installed, "disable") == [False, False], "unregister() failed or left the add-on enabled"


def test_solve_bundled_example_end_to_end(installed):
    assert EXAMPLE.exists(), f"{EXAMPLE} is missing"
    solved = _step(installed, "solve")
    assert solved["result"] == ["FINISHED"], solved
    assert solved["actions"] >= 1 and solved["max_keyframes"] > 1, solved
    cli = _step(installed, "cli")
    assert cli["exit"] == 0, (cli, installed["_log"])
    names = dict(cli["outputs"])
    stem = EXAMPLE.stem
    assert names.get(f"{stem}.json", 0) > 0 and names.get(f"{stem}.bvh", 0) > 0, cli


# ----------------------------------------------------------------------------- the loader's message

def test_loader_message_for_windows_dll_failure(monkeypatch):
    from blender_manikin.core import onnx_runtime_loader as loader

    class Blocker:
        def find_spec(self, name, path=None, target=None):
            if name == "onnxruntime":
                raise ImportError("DLL load failed while importing onnxruntime_pybind11_state: "
                                  "A dynamic link library (DLL) initialization routine failed.")
            return None

    monkeypatch.setattr(loader.platform, "system", lambda: "Windows")
    monkeypatch.setattr(loader.platform, "machine", lambda: "AMD64")
    saved = {k: v for k, v in sys.modules.items() if k == "onnxruntime" or k.startswith("onnxruntime.")}
    for k in saved:
        monkeypatch.delitem(sys.modules, k)
    monkeypatch.setattr(sys, "meta_path", [Blocker()] + sys.meta_path)
    with pytest.raises(loader.OnnxRuntimeUnavailable) as info:
        loader.load_onnxruntime()
    msg = str(info.value)
    assert "onnxruntime could not be loaded (DLL load failed" in msg
    assert "windows-x64" in msg
    assert "Visual C++ Redistributable" in msg and "restart Blender" in msg
    assert "blender_manikin-<version>-windows_x64.zip" in msg
    assert isinstance(info.value, ImportError)
    assert loader.import_onnxruntime is loader.load_onnxruntime


def _extension_without_onnxruntime(monkeypatch, tmp_path):
    """The loader as in an installed extension whose onnxruntime wheel is not installed."""
    from blender_manikin.core import onnx_runtime_loader as loader

    ext_dir = tmp_path / "extensions" / "user_default" / "blender_manikin"
    ext_dir.mkdir(parents=True)
    (ext_dir / "blender_manifest.toml").write_text("")

    class Missing:
        def find_spec(self, name, path=None, target=None):
            if name == "onnxruntime":
                raise ModuleNotFoundError("No module named 'onnxruntime'", name="onnxruntime")
            return None

    for k in [k for k in sys.modules if k == "onnxruntime" or k.startswith("onnxruntime.")]:
        monkeypatch.delitem(sys.modules, k)
    monkeypatch.setattr(sys, "meta_path", [Missing()] + sys.meta_path)
    monkeypatch.setattr(loader, "_PACKAGE_DIR", ext_dir)
    monkeypatch.setattr(loader, "_extension_site_packages", lambda d: None)
    return loader, ext_dir


def test_loader_message_names_the_supported_blenders_on_another_python(monkeypatch, tmp_path):
    """A future Blender on a Python the zip has no wheel for gets told which Blenders this zip serves."""
    loader, _ = _extension_without_onnxruntime(monkeypatch, tmp_path)
    real = loader.diagnostics
    monkeypatch.setattr(loader, "diagnostics", lambda kind=None, package_dir=None: {
        **real(kind, package_dir), "python": "3.14.1", "python_minor": "3.14"})
    with pytest.raises(loader.OnnxRuntimeUnavailable) as info:
        loader.load_onnxruntime()
    msg = str(info.value)
    assert "Python 3.14" in msg
    assert "Python 3.11: Blender 4.2 LTS to 5.0" in msg and "Python 3.13: Blender 5.1 and 5.2 LTS" in msg


def test_loader_message_when_the_wheel_is_missing(monkeypatch, tmp_path):
    loader, ext_dir = _extension_without_onnxruntime(monkeypatch, tmp_path)
    assert loader.install_kind(ext_dir, "blender_manikin") == "extension"
    assert loader.install_kind(tmp_path, "bl_ext.user_default.blender_manikin") == "extension"
    with pytest.raises(loader.OnnxRuntimeUnavailable) as info:
        loader.load_onnxruntime()
    msg = str(info.value)
    assert "installed as extension" in msg
    assert "Install from Disk" in msg and loader.blender_platform().replace("-", "_") in msg


# ----------------------------------------------------------------------------- a real Blender binary

def test_blender_binary_installs_the_zip_and_solves_with_its_onnxruntime(build_dir, tmp_path):
    """With a real ``blender`` (CI: Debian 13's Blender 4.3, Python 3.13, numpy 2): Blender's own
    command-line installer puts the zip into a fresh user directory, and the installed copy's
    ``cli.py`` solves the bundled example with the onnxruntime from the zip's wheels."""
    from blender_util import BLENDER_BANNER, binary_path, blender_binary
    blender, version = blender_binary()
    home = tmp_path / "home"
    env = {"PATH": binary_path(), "HOME": str(home), "LANG": "C.UTF-8"}
    for key, sub in (("RESOURCES", "resources"), ("CONFIG", "config"), ("SCRIPTS", "scripts")):
        (home / sub).mkdir(parents=True)
        env[f"BLENDER_USER_{key}"] = str(home / sub)

    def blender_run(*args, timeout=600):
        return subprocess.run([blender, *args], env=env, cwd=tmp_path, capture_output=True, text=True,
                              timeout=timeout)

    p = blender_run("-b", "--factory-startup", "--python-exit-code", "1", "--python-expr",
                    "import importlib.util, sys; sys.exit(importlib.util.find_spec('onnxruntime') is not None)")
    assert p.returncode == 0, "this Blender sees an onnxruntime before the zip is installed:\n" + p.stdout + p.stderr
    p = blender_run("--command", "extension", "install-file", "-r", "user_default", "-e", str(build_dir["zip"]))
    assert p.returncode == 0, p.stdout + p.stderr
    ext_dirs = sorted(home.glob("**/extensions/user_default/blender_manikin"))
    assert len(ext_dirs) == 1, list(home.rglob("*"))[:50]
    ext = ext_dirs[0]
    assert (ext / "blender_manifest.toml").is_file() and (ext / "cli.py").is_file()

    # Where onnxruntime comes from inside that Blender, through the add-on's loader.
    probe = tmp_path / "probe.py"
    report = tmp_path / "probe.json"
    probe.write_text(textwrap.dedent(f'''
        import importlib, json, sys
        import numpy
        loader = importlib.import_module("{EXT_MODULE}.core.onnx_runtime_loader")
        ort = loader.load_onnxruntime()
        json.dump({{"kind": loader.install_kind(), "file": ort.__file__, "version": ort.__version__,
                   "numpy": numpy.__version__, "python": "{{}}.{{}}".format(*sys.version_info[:2])}},
                  open({str(report)!r}, "w"))
    '''))
    p = blender_run("-b", "--python-exit-code", "1", "--python", str(probe))
    assert p.returncode == 0 and report.exists(), p.stdout + p.stderr
    info = json.loads(report.read_text())
    assert info["kind"] == "extension"
    assert "/extensions/.local/lib/python" in info["file"]
    assert Path(info["file"]).resolve().is_relative_to(home.resolve())
    py = tuple(int(x) for x in info["python"].split("."))
    assert info["version"] == build_addon.read_onnxruntime_pin(py)

    out = tmp_path / "out"
    p = blender_run("-b", "--python", str(ext / "cli.py"), "--", "solve", str(EXAMPLE), "--out", str(out),
                    "--format", "json,bvh,blend")
    assert p.returncode == 0, p.stdout + p.stderr
    lines = [ln for ln in p.stdout.splitlines() if not BLENDER_BANNER.match(ln)]
    assert len(lines) == 1 and lines[0].startswith(f"OK {EXAMPLE}"), p.stdout
    doc = json.loads((out / f"{EXAMPLE.stem}.json").read_text())
    assert len(doc["positions"]) > 30
    assert (out / f"{EXAMPLE.stem}.bvh").stat().st_size > 0 and (out / f"{EXAMPLE.stem}.blend").stat().st_size > 0

    # An .xror take through the same Blender: bson and fpzip come from the zip's wheels (the fpzip
    # decoder runs in a child of Blender's own Python, see core/io_xror.decompress_isolated).
    take = tmp_path / "take.xror"
    take.write_bytes(_xror_bytes(180))
    p = blender_run("-b", "--python", str(ext / "cli.py"), "--", "solve", str(take), "--out", str(out),
                    "--format", "json", "--height", "1.75")
    assert p.returncode == 0, p.stdout + p.stderr
    assert len(json.loads((out / "take.json").read_text())["positions"]) > 30
