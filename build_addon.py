#!/usr/bin/env python3
"""Build the installable Blender extension zips of blender_manikin, one per platform.

    python build_addon.py                      # all platforms into dist/
    python build_addon.py --platform linux-x64 --out /tmp/x
    python build_addon.py --offline            # fail instead of downloading a missing wheel

Each ``dist/blender_manikin-<version>-<platform>.zip`` holds

* ``blender_manifest.toml`` (schema 1.0.0), generated here: the version comes from
  ``__version__`` in ``blender_manikin/core/version.py`` (read with ``ast``, bpy is never
  imported), and ``bl_info["version"]`` must agree;
* the add-on package (no ``__pycache__``, tests, ``training/`` or ``*.pt`` checkpoints, and no
  ``core/`` module the add-on never imports: mocap preparation and evaluation code stays out),
  with the ONNX model(s) and their README under ``models/``;
* ``wheels/``: the unmodified PyPI onnxruntime wheels for that platform, one per CPython version
  the supported Blender range runs (3.11 for Blender 4.2-5.0, 3.13 for 5.1-5.2; Blender installs
  only the one matching its Python), plus the dependencies onnxruntime imports at run time (numpy
  excluded: Blender ships it).  Which ones
  that is is not guessed: the build reads the wheel's metadata and scans the modules that
  ``import onnxruntime`` loads; see docs/PACKAGING.md.  Likewise the ``.xror`` reader's codecs,
  pymongo (``bson``) and fpzip (``requirements-xror.txt``), each checked to need nothing else.

Wheels are fetched once with ``pip download --only-binary=:all: --no-deps`` into a cache
(``$BLENDER_MANIKIN_WHEEL_CACHE`` or ``~/.cache/blender_manikin/wheels``), so rebuilds are offline.
Every zip is checked with Blender's own extension validator (``blender_ext.py validate``, shipped
in the bpy wheel), plus the install-time checks Blender applies (platform, Python version, Blender
version range, wheels present); any warning fails the build.
"""
from __future__ import annotations

import argparse
import ast
import importlib.util
import os
import re
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent
PKG_DIR = ROOT / "blender_manikin"
EXTENSION_ID = "blender_manikin"
BLENDER_VERSION_MIN = "4.2.0"
# The supported Blender releases and the Python each runs: the install-time compatibility check
# is run for every one of them, with its own Python version (README: "Tested Blender versions").
BLENDER_PYTHON = {
    (4, 2, 0): (3, 11),     # 4.2 LTS
    (4, 5, 0): (3, 11),     # 4.5 LTS
    (5, 0, 1): (3, 11),
    (5, 1, 0): (3, 13),
    (5, 2, 0): (3, 13),     # 5.2 LTS
}
PYTHON_VERSIONS = tuple(sorted(set(BLENDER_PYTHON.values())))
# The onnxruntime pins, one per Python version, live in ONE place: requirements-onnxruntime.txt
# (see docs/PACKAGING.md for why 1.20.1).  Other requirements files include it with ``-r``.
PIN_FILE = ROOT / "requirements-onnxruntime.txt"
# The .xror reader's packages (pins in requirements-xror.txt) and the module each provides.
XROR_PIN_FILE = ROOT / "requirements-xror.txt"
XROR_MODULES = {"pymongo": "bson", "fpzip": "fpzip"}
LOADER_FILE = PKG_DIR / "core" / "onnx_runtime_loader.py"
VERSION_FILE = Path("core") / "version.py"
# Never shipped: Blender bundles numpy and an add-on must use that one.
PROVIDED_BY_BLENDER = {"numpy"}

TAGLINE = "Full-body animation from VR trackers, model CC BY-NC-ND 4.0"
PERMISSIONS = {"files": "Read VR tracker recordings and write animation files"}
LICENSE = ["SPDX:MIT"]
TAGS = ["Animation"]


def _mac_tags(arch: str) -> list[str]:
    tags = [f"macosx_{major}_0_{a}" for major in range(15, 10, -1) for a in (arch, "universal2")]
    if arch == "x86_64":     # Intel wheels are often tagged for macOS 10.x (fpzip, pymongo)
        tags += [f"macosx_10_{minor}_{a}" for minor in range(15, 8, -1) for a in (arch, "universal2")]
    return tags


# Blender platform -> pip --platform tags (most specific first) and PEP 508 marker environment.
PLATFORMS: dict[str, dict] = {
    "linux-x64": {
        "pip": ["manylinux_2_28_x86_64", "manylinux_2_27_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
        "env": {"sys_platform": "linux", "platform_system": "Linux", "platform_machine": "x86_64", "os_name": "posix"},
    },
    "windows-x64": {
        "pip": ["win_amd64"],
        "env": {"sys_platform": "win32", "platform_system": "Windows", "platform_machine": "AMD64", "os_name": "nt"},
    },
    "macos-arm64": {
        "pip": _mac_tags("arm64"),
        "env": {"sys_platform": "darwin", "platform_system": "Darwin", "platform_machine": "arm64", "os_name": "posix"},
    },
    "macos-x64": {
        "pip": _mac_tags("x86_64"),
        "env": {"sys_platform": "darwin", "platform_system": "Darwin", "platform_machine": "x86_64",
                "os_name": "posix"},
    },
}

# What never goes into the zip.
EXCLUDED_DIR_NAMES = {"__pycache__", "tests", ".pytest_cache", ".hypothesis"}
EXCLUDED_TOP_DIRS = {"training"}          # blender_manikin/training/: training-only code
EXCLUDED_SUFFIXES = {".pyc", ".pyo", ".pt", ".pth", ".ckpt", ".blend1", ".orig", ".rej", ".swp"}
# Under models/ only the shipped model files and their documentation.
MODEL_SUFFIXES = {".onnx", ".data", ".md", ".txt", ".json"}

ZIP_DATE = (1980, 1, 1, 0, 0, 0)          # fixed timestamps: identical inputs give identical zips


class BuildError(RuntimeError):
    pass


# ----------------------------------------------------------------------------- metadata

def read_version(pkg_dir: Path | None = None) -> str:
    """``__version__`` of the package, parsed from ``core/version.py`` (not imported), checked
    against ``bl_info["version"]`` of its ``__init__.py``."""
    pkg_dir = Path(pkg_dir or PKG_DIR)
    if pkg_dir.name == "__init__.py":          # older callers passed the __init__ file
        pkg_dir = pkg_dir.parent
    path = pkg_dir / VERSION_FILE
    if not path.is_file():
        raise BuildError(f"{path}: missing (the package version is written there)")
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    for node in tree.body:
        is_version = isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__version__" for t in node.targets)
        if is_version:
            value = ast.literal_eval(node.value)
            if not isinstance(value, str) or not re.fullmatch(r"\d+\.\d+\.\d+", value):
                raise BuildError(f"{path}: __version__ must be 'MAJOR.MINOR.PATCH', found {value!r}")
            info = read_bl_info(pkg_dir / "__init__.py")
            if info and tuple(info.get("version", ())) != tuple(int(x) for x in value.split(".")):
                raise BuildError(f"{pkg_dir / '__init__.py'}: bl_info version {info.get('version')} disagrees with "
                                 f"__version__ {value!r} of {path}")
            return value
    raise BuildError(f"{path}: no top-level __version__ = '...'")


def read_bl_info(init_py: Path | None = None) -> dict:
    init_py = init_py or PKG_DIR / "__init__.py"
    tree = ast.parse(init_py.read_text(encoding="utf-8"), str(init_py))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "bl_info" for t in node.targets):
            return ast.literal_eval(node.value)
    return {}


_PIN_LINE = re.compile(r"""\s*onnxruntime\s*==\s*([0-9][0-9A-Za-z.]*)\s*"""
                       r"""(?:;\s*python_version\s*==\s*["'](\d+)\.(\d+)["'])?\s*(?:#.*)?$""")


def _pins_in(path: Path) -> dict[tuple[int, int] | None, str]:
    """``onnxruntime==X`` lines of a requirements file: {(major, minor) or None: version}."""
    pins = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        if not re.match(r"\s*onnxruntime\b", line):
            continue
        m = _PIN_LINE.match(line)
        if m is None:
            raise BuildError(f"{path.name}: cannot read the onnxruntime pin {line.strip()!r}: expected "
                             "'onnxruntime==X.Y.Z; python_version == \"3.NN\"'")
        key = (int(m.group(2)), int(m.group(3))) if m.group(2) else None
        pins[key] = m.group(1)
    return pins


def _loader_pins(loader: Path) -> dict[tuple[int, int], str]:
    """``BUNDLED_ONNXRUNTIME`` of onnx_runtime_loader.py (parsed, not imported)."""
    tree = ast.parse(loader.read_text(encoding="utf-8"), str(loader))
    for node in tree.body:
        if isinstance(node, ast.AnnAssign | ast.Assign):
            targets = [node.target] if isinstance(node, ast.AnnAssign) else node.targets
            if any(isinstance(t, ast.Name) and t.id == "BUNDLED_ONNXRUNTIME" for t in targets):
                value = ast.literal_eval(node.value)
                return {tuple(int(x) for x in k.split(".")): v for k, v in value.items()}
    raise BuildError(f"{loader}: no BUNDLED_ONNXRUNTIME = {{...}}")


def read_onnxruntime_pins(pin_file: Path | None = None, loader: Path | None = None) -> dict[tuple[int, int], str]:
    """The onnxruntime version to bundle for each Python version: the pins in
    requirements-onnxruntime.txt, one per entry of :data:`PYTHON_VERSIONS`.

    The build refuses to go on if any other requirements file pins onnxruntime itself (they must
    include the pin file with ``-r``) or if ``onnx_runtime_loader.BUNDLED_ONNXRUNTIME``, which the
    add-on's error messages quote, disagrees."""
    pin_file = pin_file or PIN_FILE
    pins = _pins_in(pin_file)
    if None in pins:
        raise BuildError(f"{pin_file.name}: every onnxruntime pin needs a '; python_version == \"3.NN\"' marker")
    missing = [v for v in PYTHON_VERSIONS if v not in pins]
    if missing:
        raise BuildError(f"{pin_file.name}: no onnxruntime pin for Python "
                         + ", ".join("{}.{}".format(*v) for v in missing))
    for other in sorted(pin_file.parent.glob("requirements*.txt")):
        if other.resolve() != pin_file.resolve() and _pins_in(other):
            raise BuildError(f"{other.name} pins onnxruntime itself; include {pin_file.name} with '-r' instead")
    loader_pins = _loader_pins(loader or (pin_file.parent / LOADER_FILE.relative_to(ROOT)))
    if loader_pins != {v: pins[v] for v in PYTHON_VERSIONS}:
        raise BuildError(f"onnx_runtime_loader.BUNDLED_ONNXRUNTIME {loader_pins} disagrees with "
                         f"{pin_file.name} {pins}")
    return {v: pins[v] for v in PYTHON_VERSIONS}


def read_xror_pins(pin_file: Path | None = None) -> dict[str, str]:
    """``{distribution: version}`` of requirements-xror.txt (one ``name==X.Y.Z`` per line), for
    the distributions of :data:`XROR_MODULES`."""
    pin_file = pin_file or XROR_PIN_FILE
    pins = {}
    for line in pin_file.read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        m = re.fullmatch(r"([A-Za-z0-9_.\-]+)\s*==\s*([0-9][0-9A-Za-z.]*)", line)
        if not m or _normalize(m.group(1)) not in XROR_MODULES:
            raise BuildError(f"{pin_file.name}: expected 'NAME==X.Y.Z' for one of {sorted(XROR_MODULES)}, "
                             f"found {line!r}")
        pins[_normalize(m.group(1))] = m.group(2)
    if set(pins) != set(XROR_MODULES):
        raise BuildError(f"{pin_file.name}: pins {sorted(pins)}, expected {sorted(XROR_MODULES)}")
    return pins


def read_onnxruntime_pin(python_version: tuple[int, int] = (3, 11)) -> str:
    """The onnxruntime version bundled for one Python version (default 3.11)."""
    return read_onnxruntime_pins()[tuple(python_version[:2])]


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def manifest_text(version: str, platform: str, wheel_names: list[str], pkg_dir: Path | None = None) -> str:
    bl_info = read_bl_info((pkg_dir or PKG_DIR) / "__init__.py")
    name = bl_info.get("name", "MANIKIN full-body solver")
    maintainer = bl_info.get("author", "blender_manikin developers")
    lines = [
        "# Generated by build_addon.py: edit that script, not this file.",
        "# Code: MIT. The bundled network weights (models/) are derived from data under",
        "# CC BY-NC-ND 4.0: non-commercial use only; see models/README.md.",
        'schema_version = "1.0.0"',
        "",
        f"id = {_toml_str(EXTENSION_ID)}",
        f"version = {_toml_str(version)}",
        f"name = {_toml_str(name)}",
        f"tagline = {_toml_str(TAGLINE)}",
        f"maintainer = {_toml_str(maintainer)}",
        'type = "add-on"',
        "tags = [" + ", ".join(_toml_str(t) for t in TAGS) + "]",
        f"blender_version_min = {_toml_str(BLENDER_VERSION_MIN)}",
        "license = [" + ", ".join(_toml_str(x) for x in LICENSE) + "]",
        f"platforms = [{_toml_str(platform)}]",
        "wheels = [" + ", ".join(_toml_str("./wheels/" + w) for w in wheel_names) + "]",
        "",
        "[permissions]",
        *(f"{k} = {_toml_str(v)}" for k, v in PERMISSIONS.items()),
        "",
    ]
    return "\n".join(lines)


# ----------------------------------------------------------------------------- package files

def package_files(pkg_dir: Path | None = None) -> tuple[list[tuple[Path, str]], list[str]]:
    """(source path, archive name) pairs of the add-on package, and the notable skipped paths."""
    pkg_dir = pkg_dir or PKG_DIR
    files: list[tuple[Path, str]] = []
    skipped: list[str] = []
    for dirpath, dirnames, filenames in os.walk(pkg_dir):
        rel_dir = Path(dirpath).relative_to(pkg_dir)
        keep = []
        for d in sorted(dirnames):
            if d in EXCLUDED_DIR_NAMES or d.startswith("."):
                continue
            if rel_dir == Path(".") and d in EXCLUDED_TOP_DIRS:
                skipped.append(f"{d}/ (training-only code)")
                continue
            keep.append(d)
        dirnames[:] = keep
        for f in sorted(filenames):
            src = Path(dirpath) / f
            rel = (rel_dir / f).as_posix()
            if f.startswith(".") or src.suffix in EXCLUDED_SUFFIXES or f.endswith(".zip"):
                if src.suffix in {".pt", ".pth", ".ckpt"}:
                    skipped.append(f"{rel} (checkpoint)")
                continue
            if rel_dir.parts[:1] == ("models",) and src.suffix.lower() not in MODEL_SUFFIXES:
                skipped.append(f"{rel} (not a model file)")
                continue
            files.append((src, rel))
    if not any(rel == "__init__.py" for _, rel in files):
        raise BuildError(f"{pkg_dir}/__init__.py missing")
    unused = unused_core_modules(files)
    files = [(src, rel) for src, rel in files if rel not in unused]
    skipped += [f"{rel} (not used by the add-on)" for rel in sorted(unused)]
    # The repository's licence text travels with the code.
    licence = ROOT / "LICENSE"
    if licence.is_file() and not any(rel == "LICENSE" for _, rel in files):
        files.append((licence, "LICENSE"))
    return files, skipped


def _relative_targets(node, package):
    """Package-relative module paths (lists of names) a relative ``from`` import reaches."""
    base = package[: len(package) - (node.level - 1)] if node.level - 1 <= len(package) else None
    if base is None:
        return []
    return [base + node.module.split(".")] if node.module else [base + [a.name] for a in node.names]


def unused_core_modules(files: list[tuple[Path, str]]) -> set[str]:
    """Archive names of the ``core/`` modules that nothing outside ``core/`` reaches through
    imports (mocap preparation and evaluation code: the BVH and ASF readers, joint maps, metrics,
    baselines), so they stay out of the zip."""
    py = {rel: src for src, rel in files if rel.endswith(".py")}

    def module_file(stem):
        for cand in ("/".join(stem) + ".py", "/".join(stem) + "/__init__.py"):
            if cand in py:
                return cand
        return None

    graph = {}
    for rel, src in py.items():
        package = list(Path(rel).parent.parts)
        targets = set()
        for node in ast.walk(ast.parse(src.read_text(encoding="utf-8"), str(src))):
            if isinstance(node, ast.ImportFrom) and node.level:
                for stem in _relative_targets(node, package):
                    targets.add(module_file(stem))
                    if node.module:            # from .pkg import module
                        targets.update(module_file(stem + [a.name]) for a in node.names)
        graph[rel] = targets - {None}
    seen, todo = set(), [rel for rel in py if not rel.startswith("core/")]
    while todo:
        rel = todo.pop()
        if rel not in seen:
            seen.add(rel)
            todo.extend(graph.get(rel, ()))
    return {rel for rel in py if rel.startswith("core/") and rel not in seen and rel != "core/__init__.py"}


def check_imports(files: list[tuple[Path, str]]) -> None:
    """An extension is imported as ``bl_ext.<repo>.blender_manikin``: absolute imports of
    ``blender_manikin`` would not find it (or would find some other copy).  Nothing shipped may
    import the training code, which is not shipped.  And ``core/`` stays the Blender-free core:
    none of its modules imports bpy or anything of the package outside ``core/``."""
    bad = []
    for src, rel in files:
        if src.suffix != ".py":
            continue
        tree = ast.parse(src.read_text(encoding="utf-8"), str(src))
        package = list(Path(rel).parent.parts)          # package path inside the add-on
        in_core = package[:1] == ["core"]
        for node in ast.walk(tree):
            if in_core:
                if isinstance(node, ast.Import) and any(a.name.split(".")[0] in ("bpy", "bmesh", "mathutils")
                                                        for a in node.names):
                    bad.append(f"{rel}:{node.lineno}: core/ imports Blender's modules")
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and \
                        (node.module or "").split(".")[0] in ("bpy", "bmesh", "mathutils"):
                    bad.append(f"{rel}:{node.lineno}: core/ imports Blender's modules")
                elif isinstance(node, ast.ImportFrom) and node.level:
                    for stem in _relative_targets(node, package):
                        if stem[:1] != ["core"]:
                            bad.append(f"{rel}:{node.lineno}: core/ imports {'.'.join(stem) or 'the package root'}, "
                                       "outside core/")
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            elif isinstance(node, ast.ImportFrom):
                for stem in _relative_targets(node, package):
                    if stem[:1] and stem[0] in EXCLUDED_TOP_DIRS:
                        bad.append(f"{rel}:{node.lineno}: imports {'.'.join(stem)}, which is not shipped")
                continue
            else:
                continue
            for n in names:
                if n == EXTENSION_ID or n.startswith(EXTENSION_ID + "."):
                    bad.append(f"{rel}:{node.lineno}: import {n} (absolute; use a relative import)")
    if bad:
        raise BuildError("packaged code would break inside Blender:\n  " + "\n  ".join(bad))


# ----------------------------------------------------------------------------- wheels

def _normalize(name: str) -> str:
    return re.sub(r"[-_.]+", "_", name).lower()


def _wheel_tags(filename: str) -> tuple[str, str, str, str, str]:
    """(distribution, version, python tag, abi tag, platform tag) of a wheel file name."""
    parts = filename[:-4].split("-")
    return _normalize(parts[0]), parts[1], parts[-3], parts[-2], parts[-1]


def _wheel_fits_python(filename: str, python_version: tuple[int, int]) -> bool:
    """Whether a wheel installs on CPython ``python_version``: its own ``cpXY`` build, a stable-ABI
    (``abi3``) build for an older or equal CPython, or a pure-Python ``py3`` wheel."""
    _, _, py_tags, abi, _ = _wheel_tags(filename)
    major, minor = python_version
    for tag in py_tags.split("."):
        if tag in (f"py{major}", f"py{major}{minor}", f"cp{major}{minor}"):
            return True
        m = re.fullmatch(r"cp(\d)(\d+)", tag)
        if m and abi == "abi3" and (int(m.group(1)), int(m.group(2))) <= python_version:
            return True
    return False


def _specifier_set(spec: str):
    try:
        from packaging.specifiers import SpecifierSet
        from packaging.version import Version
    except ImportError:  # pip always vendors it
        from pip._vendor.packaging.specifiers import SpecifierSet
        from pip._vendor.packaging.version import Version
    return SpecifierSet(spec), Version


def _wheel_matches(filename: str, dist: str, spec: str, platform: str, python_version: tuple[int, int]) -> bool:
    if not filename.endswith(".whl"):
        return False
    w_dist, w_ver, _py, _abi, w_plat = _wheel_tags(filename)
    specifiers, _ = _specifier_set(spec)
    if w_dist != _normalize(dist) or not specifiers.contains(w_ver):
        return False
    if not _wheel_fits_python(filename, python_version):
        return False
    allowed = set(PLATFORMS[platform]["pip"]) | {"any"}
    return any(p in allowed for p in w_plat.split("."))


def _cached(dest: Path, dist: str, spec: str, platform: str, python_version: tuple[int, int]) -> Path | None:
    _, Version = _specifier_set("")
    found = [p for p in dest.iterdir() if _wheel_matches(p.name, dist, spec, platform, python_version)]
    return max(found, key=lambda p: Version(_wheel_tags(p.name)[1])) if found else None


def fetch_wheel(dist: str, spec: str, platform: str, cache: Path, offline: bool,
                python_version: tuple[int, int] = (3, 11)) -> Path:
    """The cached wheel of ``dist`` (newest satisfying ``spec``, e.g. "==1.20.1" or "") for
    ``platform`` and CPython ``python_version``; downloaded once, then reused (so rebuilds are
    offline)."""
    dest = cache / platform
    dest.mkdir(parents=True, exist_ok=True)
    hit = _cached(dest, dist, spec, platform, python_version)
    if hit is not None:
        return hit
    req = f"{dist}{spec}"
    py = "{}.{}".format(*python_version)
    if offline:
        raise BuildError(f"{req} for {platform}, Python {py} is not in the wheel cache {dest} (--offline)")
    cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check",
           "--only-binary=:all:", "--no-deps", "--implementation", "cp", "--python-version", py,
           "--abi", "cp{}{}".format(*python_version), "--abi", "abi3", "--abi", "none"]
    for tag in PLATFORMS[platform]["pip"]:
        cmd += ["--platform", tag]
    cmd += ["--dest", str(dest), req]
    print(f"  downloading {req} for {platform}, Python {py}", flush=True)
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise BuildError(f"pip download {req} ({platform}, Python {py}) failed:\n{proc.stdout}{proc.stderr}")
    hit = _cached(dest, dist, spec, platform, python_version)
    if hit is None:
        raise BuildError(f"pip download {req} ({platform}, Python {py}) gave no matching wheel in {dest}")
    return hit


def wheel_metadata(wheel: Path) -> str:
    with zipfile.ZipFile(wheel) as zf:
        name = next(n for n in zf.namelist() if n.count("/") == 1 and n.endswith(".dist-info/METADATA"))
        return zf.read(name).decode("utf-8")


def _requirement_tools():
    try:
        from packaging.requirements import Requirement
    except ImportError:  # pip always vendors it
        from pip._vendor.packaging.requirements import Requirement
    return Requirement


def declared_requirements(wheel: Path, platform: str,
                          python_version: tuple[int, int] = (3, 11)) -> list[tuple[str, str]]:
    """(distribution, specifier) of the wheel's Requires-Dist that apply on ``platform`` and
    CPython ``python_version``."""
    Requirement = _requirement_tools()
    env = dict(PLATFORMS[platform]["env"])
    env.update({"python_version": "{}.{}".format(*python_version),
                "python_full_version": "{}.{}.0".format(*python_version),
                "implementation_name": "cpython", "platform_python_implementation": "CPython", "extra": ""})
    out = []
    for line in wheel_metadata(wheel).splitlines():
        if not line.startswith("Requires-Dist:"):
            continue
        req = Requirement(line.split(":", 1)[1].strip())
        if req.marker is not None and not req.marker.evaluate(env):
            continue
        out.append((req.name, str(req.specifier)))
    return out


def runtime_imports(wheel: Path, top: str = "onnxruntime") -> set[str]:
    """Top-level names of the third-party modules that ``import <top>`` can load.

    Follows the package's own modules from ``<top>/__init__.py`` through every import statement
    (module level and inside functions: conservative) and collects the imports that leave the
    package and the standard library."""
    with zipfile.ZipFile(wheel) as zf:
        sources = {}
        for n in zf.namelist():
            if n.startswith(top + "/") and n.endswith(".py"):
                mod = n[:-3].replace("/", ".")
                if mod.endswith(".__init__"):
                    mod = mod[: -len(".__init__")]
                sources[mod] = (zf.read(n), n.endswith("__init__.py"))
    stdlib = set(sys.stdlib_module_names)
    seen: set[str] = set()
    todo = [top]
    external: set[str] = set()
    while todo:
        mod = todo.pop()
        if mod in seen or mod not in sources:
            continue
        seen.add(mod)
        src, is_pkg = sources[mod]
        package = mod if is_pkg else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(src)):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")
                    base = base[: len(base) - (node.level - 1)]
                    stem = ".".join(base + ([node.module] if node.module else []))
                else:
                    stem = node.module or ""
                targets = [stem] + [f"{stem}.{a.name}" for a in node.names]
            for t in targets:
                head = t.split(".")[0]
                if head == top:
                    # enqueue the module and its parent packages
                    parts = t.split(".")
                    todo.extend(".".join(parts[: i + 1]) for i in range(len(parts)))
                elif head and head not in stdlib and head != "__future__":
                    external.add(head)
    return external


def top_level_names(wheel: Path) -> set[str]:
    with zipfile.ZipFile(wheel) as zf:
        names = set()
        for n in zf.namelist():
            first = n.split("/")[0]
            if first.endswith((".dist-info", ".data")):
                continue
            names.add(first[:-3] if first.endswith(".py") else first.split(".")[0])
        return names


def check_windows_msvc_runtime(wheel: Path) -> str:
    """Refuse Windows binaries that need msvcp140.dll 14.40+.

    MSVC 17.10 made ``std::mutex``'s constructor constexpr; binaries built that way crash or fail
    with "DLL initialization routine failed" when an older msvcp140.dll is already loaded, and
    Blender 4.2 LTS to 5.0 load their own 14.29 copy from ``blender.crt`` (so installing a newer
    VC++ redistributable does not help).  Such binaries no longer import ``_Mtx_init_in_situ``
    (the run-time mutex constructor) although they still import ``_Mtx_lock``.  onnxruntime up to
    1.20.1 import both; 1.21.0 and newer only ``_Mtx_lock``.  See docs/PACKAGING.md."""
    checked = []
    with zipfile.ZipFile(wheel) as zf:
        for name in zf.namelist():
            if not name.lower().endswith((".dll", ".pyd")):
                continue
            data = zf.read(name)
            if b"_Mtx_lock\x00" in data:
                if b"_Mtx_init_in_situ\x00" not in data:
                    raise BuildError(
                        f"{wheel.name}: {name} is built with constexpr std::mutex (MSVC 17.10+): it needs "
                        "msvcp140.dll 14.40+, newer than the one Blender 4.2-5.0 load, and fails there with "
                        "'DLL initialization routine failed'. Keep onnxruntime<=1.20.1 (docs/PACKAGING.md).")
                checked.append(name.rsplit("/", 1)[-1])
    return ("Windows runtime check: {} construct std::mutex at run time (_Mtx_init_in_situ): "
            "fine with Blender's msvcp140 14.29".format(", ".join(checked)) if checked
            else "Windows runtime check: no binary uses std::mutex")


def resolve_wheels_for_python(platform: str, python_version: tuple[int, int], ort_version: str, cache: Path,
                              offline: bool, all_deps: bool) -> tuple[list[Path], list[str]]:
    """Wheels to ship for ``platform`` and one CPython version, and an account of the decision."""
    py = "Python {}.{}".format(*python_version)
    notes = []
    ort = fetch_wheel("onnxruntime", "==" + ort_version, platform, cache, offline, python_version)
    ship = [ort]
    declared = declared_requirements(ort, platform, python_version)
    notes.append("{}: onnxruntime {} declares: {}".format(
        py, ort_version, ", ".join(n + s for n, s in declared) or "nothing"))
    needed = runtime_imports(ort) - PROVIDED_BY_BLENDER
    candidates = [(n, s) for n, s in declared if _normalize(n) not in PROVIDED_BY_BLENDER]
    specs = {_normalize(n): s for n, s in candidates}
    if all_deps:
        wanted = set(specs)
    else:
        wanted = set()
        if needed:
            # Map the imported names to the declared distributions that provide them.
            for n, spec in candidates:
                if top_level_names(fetch_wheel(n, spec, platform, cache, offline, python_version)) & needed:
                    wanted.add(_normalize(n))
        notes.append("{}: `import onnxruntime` needs at run time: {} (numpy comes with Blender)".format(
            py, ", ".join(sorted(needed)) or "nothing beyond numpy"))
    # Transitive closure of what is wanted.
    done: set[str] = set()
    queue = [(d, specs[d]) for d in sorted(wanted)]
    while queue:
        dist, spec = queue.pop(0)
        if dist in done or dist in PROVIDED_BY_BLENDER:
            continue
        done.add(dist)
        w = fetch_wheel(dist, spec, platform, cache, offline, python_version)
        ship.append(w)
        queue.extend((_normalize(n), s) for n, s in declared_requirements(w, platform, python_version))
    provided = set()
    for w in ship:
        provided |= top_level_names(w)
    missing = needed - provided
    if missing:
        raise BuildError(f"{py}: onnxruntime imports {sorted(missing)} at run time but no shipped wheel provides it")
    # The .xror reader's codecs: each wheel must bring all its module imports (beyond numpy).
    for dist, version in sorted(read_xror_pins().items()):
        w = fetch_wheel(dist, "==" + version, platform, cache, offline, python_version)
        top = XROR_MODULES[dist]
        needs = runtime_imports(w, top) - PROVIDED_BY_BLENDER - top_level_names(w)
        if needs:
            raise BuildError(f"{py}: {w.name}: `import {top}` needs {sorted(needs)}, which are not bundled")
        ship.append(w)
        notes.append(f"{py}: .xror reader: {dist} {version} (`import {top}` needs nothing else)")
    return ship, notes


def resolve_wheels(platform: str, ort_versions: dict[tuple[int, int], str], cache: Path, offline: bool,
                   all_deps: bool) -> tuple[list[Path], list[str]]:
    """Wheels to ship for ``platform``: those of every Python version in ``ort_versions``
    ({(3, 11): "1.20.1", ...}), without duplicates, and an account of the decision."""
    ship: list[Path] = []
    notes: list[str] = []
    for python_version, ort_version in sorted(ort_versions.items()):
        wheels, why = resolve_wheels_for_python(platform, python_version, ort_version, cache, offline, all_deps)
        ship.extend(w for w in wheels if w not in ship)
        notes.extend(why)
    if platform.startswith("windows"):
        notes.extend(check_windows_msvc_runtime(w) for w in ship if not w.name.endswith("-any.whl"))
    notes.append("shipped wheels: " + ", ".join(w.name for w in ship))
    return ship, notes


# ----------------------------------------------------------------------------- zip + validation

def _zip_add(zf: zipfile.ZipFile, arcname: str, data: bytes, store: bool = False) -> None:
    info = zipfile.ZipInfo(arcname, ZIP_DATE)
    info.external_attr = 0o644 << 16
    info.compress_type = zipfile.ZIP_STORED if store else zipfile.ZIP_DEFLATED
    zf.writestr(info, data, compresslevel=None if store else 9)


def write_zip(out: Path, manifest: str, files: list[tuple[Path, str]], wheels: list[Path]) -> None:
    tmp = out.with_name("." + out.name + ".tmp")
    with zipfile.ZipFile(tmp, "w") as zf:
        _zip_add(zf, "blender_manifest.toml", manifest.encode("utf-8"))
        for src, rel in files:
            big = src.suffix in {".onnx", ".data"} and src.stat().st_size > 50_000_000
            _zip_add(zf, rel, src.read_bytes(), store=big)
        for w in wheels:
            _zip_add(zf, "wheels/" + w.name, w.read_bytes(), store=True)
    os.replace(tmp, out)


def find_blender_ext(explicit: str | None = None) -> Path:
    """Blender's extension CLI, as shipped inside the bpy wheel (found without importing bpy)."""
    if explicit:
        return Path(explicit)
    spec = importlib.util.find_spec("bpy")
    roots = []
    if spec is not None and spec.submodule_search_locations:
        roots += [Path(p) for p in spec.submodule_search_locations]
    roots.append(Path(sysconfig.get_paths()["purelib"]) / "bpy")
    for root in roots:
        hits = sorted(root.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
        if hits:
            return hits[-1]
    raise BuildError("Blender's blender_ext.py not found: install bpy (requirements-test.txt) or pass --blender-ext")


def _load_blender_ext(path: Path):
    spec = importlib.util.spec_from_file_location("_manikin_blender_ext", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def validate_zip(zip_path: Path, platform: str, blender_ext_path: Path) -> str:
    """Blender's ``validate`` (with Blender's tag list, as ``blender --command extension validate``)
    plus the checks Blender runs when installing: raises BuildError on any error or warning."""
    tags = blender_ext_path.parents[3] / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    cmd = [sys.executable, str(blender_ext_path), "validate"]
    if tags.exists():
        cmd.append(f"--valid-tags={tags}")
    cmd.append(str(zip_path))
    proc = subprocess.run(cmd, capture_output=True, text=True)
    output = (proc.stdout + proc.stderr).strip()
    problems = [ln for ln in output.splitlines() if not ln.startswith("Success parsing TOML")]
    if proc.returncode != 0 or problems or "Success parsing TOML" not in output:
        raise BuildError(f"Blender validator rejected {zip_path.name} (exit {proc.returncode}):\n{output}")

    bx = _load_blender_ext(blender_ext_path)
    with zipfile.ZipFile(zip_path) as zf:
        subdir = bx.pkg_zipfile_detect_subdir_or_none(zf)
        manifest = bx.pkg_manifest_from_zipfile_and_validate_all_errors(zf, subdir, strict=True)
        if isinstance(manifest, list):
            raise BuildError(f"{zip_path.name}: manifest errors: {manifest}")
        names = set(zf.namelist())
        wheels = list(manifest.wheels or [])
        for w in wheels:
            arc = w[2:] if w.startswith("./") else w
            if arc not in names:
                raise BuildError(f"{zip_path.name}: wheel listed in the manifest is missing: {w}")
            if not bx.blender_platform_compatible_with_wheel_platform_from_filepath(platform, w):
                raise BuildError(f"{zip_path.name}: wheel {w} is not for {platform}")
        for n in names:
            if n.startswith("wheels/") and "./" + n not in wheels:
                raise BuildError(f"{zip_path.name}: {n} is not listed in the manifest")
        py_versions = bx.python_versions_from_wheels(wheels) if wheels else set()
        if isinstance(py_versions, str):
            raise BuildError(f"{zip_path.name}: {py_versions}")
        item = manifest._asdict()
        item["python_versions"] = sorted(".".join(map(str, v)) for v in py_versions)
        for bver, pyver in sorted(BLENDER_PYTHON.items()):
            label = "Blender {}.{} (Python {}.{})".format(*bver[:2], *pyver)
            if wheels and "{}.{}".format(*pyver) not in item["python_versions"]:
                raise BuildError(f"{zip_path.name}: no wheels for {label}: {item['python_versions']}")
            msgs: list[str] = []
            skip = bx.repository_filter_skip(
                item, filter_blender_version=bver, filter_platform=platform,
                filter_python_version=(*pyver, 0),
                skip_message_fn=msgs.append, error_fn=lambda ex: msgs.append(str(ex)))
            if skip or msgs:
                raise BuildError(f"{zip_path.name}: {label} would refuse it: {msgs}")
            # What that Blender installs: the wheels whose Python tags fit its Python.  Exactly one
            # onnxruntime, or the add-on would load none or a wrong one.
            names = [w.rsplit("/", 1)[-1] for w in wheels]
            ort = [n for n in names if _wheel_tags(n)[0] == "onnxruntime" and _wheel_fits_python(n, pyver)]
            if len(ort) != 1:
                raise BuildError(f"{zip_path.name}: {label} would install {len(ort)} onnxruntime wheels: {ort}")
            for dist in XROR_MODULES:      # and the .xror reader's codecs, once each
                got = [n for n in names if _normalize(_wheel_tags(n)[0]) == dist and _wheel_fits_python(n, pyver)]
                if len(got) != 1:
                    raise BuildError(f"{zip_path.name}: {label} would install {len(got)} {dist} wheels: {got}")
    return output


# ----------------------------------------------------------------------------- main

def zip_name(version: str, platform: str) -> str:
    return f"{EXTENSION_ID}-{version}-{platform.replace('-', '_')}.zip"


def build(platforms: list[str], out_dir: Path, cache: Path, offline: bool = False, all_deps: bool = False,
          blender_ext: str | None = None, quiet: bool = False, pkg_dir: Path | None = None) -> list[Path]:
    """Build and validate one zip per platform; returns their paths.  ``pkg_dir`` (default: the
    repository's blender_manikin/) lets tests package a modified copy."""
    log = (lambda *a: None) if quiet else (lambda *a: print(*a, flush=True))
    pkg_dir = pkg_dir or PKG_DIR
    version = read_version(pkg_dir)
    ort_versions = read_onnxruntime_pins()
    files, skipped = package_files(pkg_dir)
    check_imports(files)
    models = [rel for _, rel in files if rel.startswith("models/")]
    log(f"blender_manikin {version}: {len(files)} package files; models: {', '.join(models) or 'none yet'}")
    for s in skipped:
        log(f"  not packaged: {s}")
    bx_path = find_blender_ext(blender_ext)
    out_dir.mkdir(parents=True, exist_ok=True)
    built = []
    for platform in platforms:
        wheels, notes = resolve_wheels(platform, ort_versions, cache, offline, all_deps)
        for n in notes:
            log(f"  [{platform}] {n}")
        out = out_dir / zip_name(version, platform)
        write_zip(out, manifest_text(version, platform, [w.name for w in wheels], pkg_dir), files, wheels)
        report = validate_zip(out, platform, bx_path)
        log(f"  [{platform}] Blender {bx_path.parents[4].name} validator: {report}")
        built.append(out)
    return built


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--platform", action="append", choices=sorted(PLATFORMS),
                    help="build only this platform (repeatable); default: all")
    ap.add_argument("--out", type=Path, default=ROOT / "dist", help="output directory (default: dist/)")
    ap.add_argument("--cache", type=Path, default=Path(os.environ.get(
        "BLENDER_MANIKIN_WHEEL_CACHE", Path.home() / ".cache" / "blender_manikin" / "wheels")),
        help="wheel cache (default: $BLENDER_MANIKIN_WHEEL_CACHE or ~/.cache/blender_manikin/wheels)")
    ap.add_argument("--offline", action="store_true", help="never download: fail if a wheel is not cached")
    ap.add_argument("--all-deps", action="store_true",
                    help="ship every declared dependency of onnxruntime (except numpy), not only those it imports")
    ap.add_argument("--blender-ext", help="path to Blender's blender_ext.py (default: the one in the bpy wheel)")
    args = ap.parse_args(argv)
    platforms = args.platform or list(PLATFORMS)
    try:
        built = build(platforms, args.out, args.cache, args.offline, args.all_deps, args.blender_ext)
    except BuildError as ex:
        print(f"build_addon.py: error: {ex}", file=sys.stderr)
        return 1
    print("built:")
    for p in built:
        print(f"  {p.relative_to(ROOT) if p.is_relative_to(ROOT) else p}  {p.stat().st_size:,} bytes "
              f"({p.stat().st_size / 2**20:.1f} MiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
