"""Load onnxruntime for the add-on, or fail with a message a user can act on.

Operators should not ``import onnxruntime`` themselves but do::

    from ..core.onnx_runtime_loader import OnnxRuntimeUnavailable, load_onnxruntime
    try:
        ort = load_onnxruntime()
    except OnnxRuntimeUnavailable as ex:
        self.report({'ERROR'}, str(ex))
        return {'CANCELLED'}

How the add-on got onnxruntime is detected from what is on disk, never from version numbers:

* extension (Blender 4.2+ zip with ``blender_manifest.toml``): Blender installs the bundled
  wheels into ``<extensions>/.local/lib/pythonX.Y/site-packages`` and puts that on ``sys.path``;
* legacy add-on: a ``_vendor/`` folder inside the package, if one was shipped, is put on
  ``sys.path``; otherwise onnxruntime must already be importable from Blender's Python;
* plain Python (tests, the batch CLI): whatever the environment provides.

No bpy import at module level: the CLI and the tests use this module outside Blender.
"""
from __future__ import annotations

import importlib
import os
import platform
import sys
from pathlib import Path

__all__ = ["OnnxRuntimeUnavailable", "load_onnxruntime", "import_onnxruntime", "install_kind",
           "blender_platform", "diagnostics"]

# The onnxruntime the extension zips bundle, per Python version ("3.11": Blender 4.2-5.0,
# "3.13": Blender 5.1-5.2).  The pins themselves live in requirements-onnxruntime.txt; this copy is
# only quoted in messages, and build_addon.py refuses to build when the two disagree.
BUNDLED_ONNXRUNTIME = {"3.11": "1.20.1", "3.13": "1.20.1"}
# The Blender releases each bundled Python version serves (for the messages).
BLENDER_FOR_PYTHON = {"3.11": "Blender 4.2 LTS to 5.0", "3.13": "Blender 5.1 and 5.2 LTS"}

_PACKAGE_DIR = Path(__file__).resolve().parent.parent     # blender_manikin/ (this file is in core/)
_MANIFEST = "blender_manifest.toml"


class OnnxRuntimeUnavailable(ImportError):
    """onnxruntime could not be imported. ``str(ex)`` is the message to show the user:
    what failed, on which platform, and what to do about it."""

    def __init__(self, message: str, *, cause: BaseException | None = None, details: dict | None = None):
        super().__init__(message)
        self.cause = cause
        self.details = details or {}


def blender_platform() -> str:
    """This machine as Blender names platforms: linux-x64, windows-x64, macos-arm64, ..."""
    system = {"darwin": "macos"}.get(platform.system().lower(), platform.system().lower())
    machine = platform.machine().lower()
    machine = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64"}.get(machine, machine)
    return f"{system}-{machine}"


def install_kind(package_dir: Path | None = None, package_name: str | None = None) -> str:
    """'extension', 'legacy' or 'module' (imported outside Blender's add-on machinery)."""
    package_dir = package_dir or _PACKAGE_DIR
    package_name = package_name if package_name is not None else (__package__ or "").rpartition(".core")[0]
    if (package_dir / _MANIFEST).is_file() or package_name.startswith("bl_ext."):
        return "extension"
    if "bpy" in sys.modules and any(
            Path(p).resolve() == package_dir.parent.resolve() for p in _addon_dirs()):
        return "legacy"
    return "module"


def _addon_dirs() -> list[str]:
    try:
        import addon_utils  # Blender's own module
        return list(addon_utils.paths())
    except Exception:
        return []


def _extension_site_packages(package_dir: Path) -> Path | None:
    """Where Blender installs extension wheels, if this is an extension."""
    version = "python{}.{}".format(*sys.version_info[:2])
    candidates = []
    bpy = sys.modules.get("bpy")  # only when running inside Blender; never imported here
    if bpy is not None:
        try:
            candidates.append(Path(bpy.utils.user_resource('EXTENSIONS', path=".local")))
        except Exception:
            pass
    # <extensions>/<repo>/<id>/ -> <extensions>/.local
    candidates.append(package_dir.parent.parent / ".local")
    for local in candidates:
        sp = local / "lib" / version / "site-packages"
        if sp.is_dir():
            return sp
    return None


def _prepare_sys_path(kind: str, package_dir: Path) -> Path | None:
    """Make the onnxruntime that belongs to this install importable; return its directory."""
    if kind == "extension":
        sp = _extension_site_packages(package_dir)
        if sp is not None and str(sp) not in sys.path:
            sys.path.append(str(sp))
        return sp
    vendor = package_dir / "_vendor"
    if vendor.is_dir():
        if str(vendor) not in sys.path:
            sys.path.insert(0, str(vendor))
        return vendor
    return None


def _forget_partial_import() -> None:
    # A failed import leaves half-initialised modules behind; drop them so that a retry
    # (after installing the VC++ runtime, say) really retries.
    for name in [m for m in sys.modules if m == "onnxruntime" or m.startswith("onnxruntime.")]:
        del sys.modules[name]
    importlib.invalidate_caches()


def _blender_version() -> str:
    bpy = sys.modules.get("bpy")
    try:
        return bpy.app.version_string if bpy is not None else "not running in Blender"
    except Exception:
        return "unknown"


def diagnostics(kind: str | None = None, package_dir: Path | None = None) -> dict:
    package_dir = package_dir or _PACKAGE_DIR
    kind = kind or install_kind(package_dir)
    return {
        "platform": blender_platform(),
        "os": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "python_minor": "{}.{}".format(*sys.version_info[:2]),
        "blender": _blender_version(),
        "install": kind,
        "package_dir": str(package_dir),
    }


def bundled_version(python: str | None = None) -> str:
    """The onnxruntime version the zips bundle for this (or the given "3.NN") Python version;
    the newest bundled one when this Python is not among them."""
    python = python or "{}.{}".format(*sys.version_info[:2])
    return BUNDLED_ONNXRUNTIME.get(python) or max(BUNDLED_ONNXRUNTIME.values())


def _unsupported_python_advice(python: str) -> str | None:
    """Advice when the zips carry no wheel for this Python version (a newer Blender)."""
    if python in BUNDLED_ONNXRUNTIME:
        return None
    served = "; ".join(f"Python {py}: {what}" for py, what in BLENDER_FOR_PYTHON.items())
    return (f"This Blender runs Python {python}, and this version of the add-on bundles onnxruntime only for "
            f"{served}. Install a release of the add-on made for this Blender, or use one of those Blender "
            "versions.")


def _advice(ex: BaseException, kind: str, details: dict, where: Path | None) -> str:
    text = f"{type(ex).__name__}: {ex}"
    plat = details["platform"]
    unsupported = _unsupported_python_advice(details["python_minor"])
    zip_hint = f"blender_manikin-<version>-{plat.replace('-', '_')}.zip"
    windows = plat.startswith("windows")
    dll = windows and ("DLL" in text or isinstance(ex, OSError) or "initialization routine" in text)
    if dll:
        return ("On Windows install the latest Microsoft Visual C++ Redistributable 2015-2022 (x64) from "
                "Microsoft, then restart Blender. If it still fails, reinstall the extension zip for your "
                f"platform ({zip_hint}), which bundles onnxruntime {bundled_version()}: newer onnxruntime "
                "releases need a newer msvcp140.dll (14.40+) than Blender 4.2-5.0 load, so do not replace it "
                "with a newer onnxruntime from pip.")
    if "numpy" in text.lower():
        return ("The onnxruntime that was found does not work with Blender's numpy. Remove other onnxruntime "
                "installs from Blender's Python and your user site-packages so that the bundled one is used, "
                f"then reinstall the extension zip for your platform ({zip_hint}).")
    if isinstance(ex, ModuleNotFoundError) and (ex.name or "").split(".")[0] == "onnxruntime":
        if kind == "extension" and unsupported:
            return unsupported
        if kind == "extension":
            where_txt = f" (looked in {where})" if where else " (no extension site-packages found)"
            return ("The onnxruntime wheel bundled with the extension is not installed" + where_txt + ". "
                    f"Reinstall the extension zip for your platform ({zip_hint}) with Edit > Preferences > "
                    "Get Extensions > Install from Disk, enable it, and restart Blender.")
        if kind == "legacy":
            return ("This copy was installed as a legacy add-on, which cannot install the bundled wheels. "
                    f"Remove it and install the extension zip for your platform ({zip_hint}) with Edit > "
                    "Preferences > Get Extensions > Install from Disk (Blender 4.2 or newer).")
        return f"Install it into this Python: pip install onnxruntime=={bundled_version()}"
    return (f"Reinstall the extension zip for your platform ({zip_hint}) and restart Blender. If the problem "
            "persists, report it with this message.")


def load_onnxruntime():
    """Import and return the onnxruntime module, or raise :class:`OnnxRuntimeUnavailable`."""
    mod = sys.modules.get("onnxruntime")
    if mod is not None and hasattr(mod, "InferenceSession"):
        return mod
    kind = install_kind()
    where = _prepare_sys_path(kind, _PACKAGE_DIR)
    try:
        import onnxruntime
        onnxruntime.InferenceSession  # noqa: B018  (fails on a half-broken install)
        return onnxruntime
    except (ImportError, OSError, AttributeError) as ex:
        _forget_partial_import()
        details = diagnostics(kind)
        first_line = str(ex).strip().splitlines()[0] if str(ex).strip() else type(ex).__name__
        message = (f"onnxruntime could not be loaded ({first_line}). "
                   f"Platform: {details['platform']}, Blender {details['blender']}, Python {details['python']}, "
                   f"installed as {details['install']}. " + _advice(ex, kind, details, where))
        details["error"] = f"{type(ex).__name__}: {ex}"
        raise OnnxRuntimeUnavailable(message, cause=ex, details=details) from ex


# The name core/model_runner.py calls.
import_onnxruntime = load_onnxruntime


if __name__ == "__main__":  # python -m blender_manikin.core.onnx_runtime_loader: quick self-check
    try:
        ort = load_onnxruntime()
        print("onnxruntime", ort.__version__, "from", os.path.dirname(ort.__file__))
    except OnnxRuntimeUnavailable as err:
        print(err, file=sys.stderr)
        sys.exit(1)
