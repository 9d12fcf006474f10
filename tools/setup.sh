#!/usr/bin/env bash
# Create (or reuse) a virtual environment with everything the add-on's tests
# and the batch converter need.  Usage: bash tools/setup.sh [VENV_DIR] [REQUIREMENTS]
# Defaults: .venv and requirements-train.txt (bpy 5.0.1, onnxruntime, pytest, plus the
# CPU build of torch 2.13.0 and onnx for the training tests; Python 3.11).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV="${1:-.venv}"
REQ="${2:-requirements-train.txt}"
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null 2>&1 || PY=python3
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q --upgrade pip >/dev/null
"$VENV/bin/python" -m pip install -q -r "$REQ"
"$VENV/bin/python" -c "import bpy, numpy, onnxruntime; print('environment ready:', '$VENV', 'Blender', bpy.app.version_string, 'numpy', numpy.__version__, 'onnxruntime', onnxruntime.__version__)"
