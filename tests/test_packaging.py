"""`pip install .`: the core package and the `blender-manikin` command (pyproject.toml)."""
import configparser
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_wheel_holds_the_core_the_model_and_the_command(tmp_path):
    # build from a copy: setuptools writes build/ and *.egg-info into the source tree
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy(os.path.join(ROOT, name), src / name)
    shutil.copytree(os.path.join(ROOT, "blender_manikin"), src / "blender_manikin",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    p = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(src)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    (whl,) = [f for f in os.listdir(tmp_path) if f.endswith(".whl")]
    from blender_manikin.core.version import __version__
    assert whl.startswith(f"blender_manikin-{__version__}-py3-none-any")
    with zipfile.ZipFile(tmp_path / whl) as zf:
        names = zf.namelist()
        meta = zf.read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
        ep = configparser.ConfigParser()
        ep.read_string(zf.read(next(n for n in names if n.endswith(".dist-info/entry_points.txt"))).decode())
    assert "blender_manikin/core/solve.py" in names and "blender_manikin/models/manikin_s.onnx" in names
    assert not any(n.startswith("tests/") for n in names)
    requires = [ln.split(":", 1)[1].strip() for ln in meta.splitlines() if ln.startswith("Requires-Dist:")]
    core = [r for r in requires if "extra ==" not in r]
    assert sorted(r.split(">")[0].split("=")[0].strip() for r in core) == ["numpy", "onnxruntime"]
    extras = {ln.split(":", 1)[1].strip() for ln in meta.splitlines() if ln.startswith("Provides-Extra:")}
    assert {"blender", "train", "dask"} <= extras
    assert ep["console_scripts"]["blender-manikin"] == "blender_manikin.cli:main"


def test_version_in_pyproject_comes_from_the_package():
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        cfg = tomllib.load(f)
    assert "version" in cfg["project"]["dynamic"]
    assert cfg["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "blender_manikin.core.version.__version__"}
