"""The extension zip: build, Blender's validator, and a real install into a fresh Blender.

The install runs in a SUBPROCESS that cannot see this environment's onnxruntime: the interpreter
is started with ``-I -S`` (no site-packages at all) and gets a path holding only symlinks to
bpy and numpy.  Blender's own installer (``bpy.ops.extensions.package_install_files``) puts the
zip into a user directory under ``tmp_path`` (BLENDER_USER_* variables), installs the bundled
wheel, and the add-on is enabled; the test then checks that the onnxruntime that got imported
is the one from the extension's site-packages, that it runs a model, and that the add-on
registered.  Solving the bundled example end to end runs once blender_manikin/models/*.onnx
exists.
"""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
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
HAS_REGISTRATION = (PKG / "blender_registration.py").exists() or (PKG / "blender_registration").is_dir()
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


# The script that runs inside the isolated interpreter.  argv: report.json zip tiny.onnx solve(0/1) example out_dir
CHILD = textwrap.dedent(r'''
    import importlib, importlib.util, json, os, sys, traceback
    report_path, zip_path, tiny_model, solve, example, out_dir = sys.argv[1:7]
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
            return {"file": onnxruntime.__file__, "version": onnxruntime.__version__, "y": y.tolist(),
                    "numpy": np.__version__, "numpy_file": np.__file__}

        @step("loader")
        def _():
            loader = importlib.import_module("''' + EXT_MODULE + r'''.onnx_runtime_loader")
            return {"kind": loader.install_kind(), "file": loader.load_onnxruntime().__file__}

        @step("registered")
        def _():
            return {"ops": sorted(dir(bpy.ops.manikin)),
                    "scene_props": sorted(p.identifier for p in bpy.types.Scene.bl_rna.properties
                                          if "manikin" in p.identifier)}

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
    """Build the linux-x64 zip (from a copy with a stub blender_registration while the real one is
    not in the tree yet, so the install path is still exercised)."""
    base = tmp_path_factory.mktemp("extension")
    pkg_dir = PKG
    if not HAS_REGISTRATION:
        pkg_dir = base / "pkg" / "blender_manikin"
        shutil.copytree(PKG, pkg_dir, ignore=shutil.ignore_patterns("__pycache__", "training", "*.pt"))
        (pkg_dir / "blender_registration.py").write_text(
            "def register():\n    pass\n\n\ndef unregister():\n    pass\n")
    (zip_path,) = build_addon.build([PLATFORM], base / "dist", _wheel_cache(), quiet=True, pkg_dir=pkg_dir)
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
    env = {
        "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
        "HOME": str(home),
        "LANG": "C.UTF-8",
        "BLENDER_USER_RESOURCES": str(home / "resources"),
        "BLENDER_USER_CONFIG": str(home / "config"),
        "BLENDER_USER_SCRIPTS": str(home / "scripts"),
    }
    solve = "1" if MODELS else "0"
    bootstrap = (f"import sys; sys.path.insert(0, {str(site)!r}); "
                 f"sys.argv = [{str(script)!r}] + sys.argv[1:]; "
                 f"exec(compile(open({str(script)!r}).read(), {str(script)!r}, 'exec'))")
    cmd = [sys.executable, "-I", "-S", "-c", bootstrap, str(report_path), str(build_dir["zip"]), str(tiny),
           solve, str(EXAMPLE), str(base / "out")]
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
    assert any(w.startswith(f"wheels/onnxruntime-{build_addon.read_onnxruntime_pin()}-cp311-") for w in wheels)
    assert not any("numpy" in w for w in wheels), "Blender ships numpy; bundling one breaks it"
    assert "__init__.py" in names and "onnx_runtime_loader.py" in names
    for n in names:
        assert "__pycache__" not in n and not n.endswith((".pyc", ".pt"))
        assert not n.startswith(("tests/", "training/"))
    for model in MODELS:
        assert f"models/{model.name}" in names


def test_version_comes_from_the_package():
    text = (PKG / "__init__.py").read_text()
    assert f'__version__ = "{build_addon.read_version()}"' in text


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
    (pkg / "core" / "bad.py").write_text("from blender_manikin.core import ok\nfrom ..training import export\n")
    files, _ = build_addon.package_files(pkg)
    with pytest.raises(build_addon.BuildError) as info:
        build_addon.check_imports(files)
    text = str(info.value)
    assert "core/bad.py:1: import blender_manikin.core (absolute" in text
    assert "core/bad.py:2: imports training, which is not shipped" in text
    assert "ok.py" not in text


def test_windows_binaries_needing_msvcp140_14_40_are_refused(tmp_path):
    """onnxruntime >= 1.21 (constexpr std::mutex, no _Mtx_init_in_situ import) cannot load in
    Blender 4.2-5.0 on Windows; the build must refuse such a wheel."""
    def fake_wheel(name, dll_imports):
        path = tmp_path / name
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("onnxruntime/capi/onnxruntime.dll", b"MZ\x00MSVCP140.dll\x00" + dll_imports)
        return path

    old_style = fake_wheel("onnxruntime-1.20.1-cp311-cp311-win_amd64.whl", b"\x00\x00_Mtx_init_in_situ\x00\x00\x00_Mtx_lock\x00")
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
    assert ort["version"] == build_addon.read_onnxruntime_pin()
    assert ort["y"] == [1.0, 4.0, 9.0]
    loader = _step(installed, "loader")
    assert loader["kind"] == "extension"
    assert Path(loader["file"]).resolve().is_relative_to(site_packages)
    assert _step(installed, "unshipped_modules_loaded") == []


def test_addon_registered(installed):
    if not HAS_REGISTRATION:
        pytest.skip("blender_manikin/blender_registration.py is not in the tree yet (installed with a stub)")
    reg = _step(installed, "registered")
    assert reg["ops"] or reg["scene_props"], "the add-on registered no bpy.ops.manikin operator and no scene property"
    assert _step(installed, "disable") == [False, False], "unregister() failed or left the add-on enabled"


def test_solve_bundled_example_end_to_end(installed):
    if not MODELS:
        pytest.skip("blender_manikin/models/*.onnx is not there yet")
    assert EXAMPLE.exists(), f"a model is shipped but {EXAMPLE} is missing"
    assert HAS_REGISTRATION, "a model is shipped but blender_registration.py is missing"
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
    from blender_manikin import onnx_runtime_loader as loader

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


def test_loader_message_when_the_wheel_is_missing(monkeypatch, tmp_path):
    from blender_manikin import onnx_runtime_loader as loader

    ext_dir = tmp_path / "extensions" / "user_default" / "blender_manikin"
    ext_dir.mkdir(parents=True)
    (ext_dir / "blender_manifest.toml").write_text("")
    assert loader.install_kind(ext_dir, "blender_manikin") == "extension"
    assert loader.install_kind(tmp_path, "bl_ext.user_default.blender_manikin") == "extension"

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
    with pytest.raises(loader.OnnxRuntimeUnavailable) as info:
        loader.load_onnxruntime()
    msg = str(info.value)
    assert "installed as extension" in msg
    assert "Install from Disk" in msg and loader.blender_platform().replace("-", "_") in msg
