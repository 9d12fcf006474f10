#!/usr/bin/env bash
# Every operator of the add-on in a real Blender window: undo / redo give the scene back, and
# nothing the user made is overwritten or lost (tools/gui_userdata_check.py says what is checked).
#
#   bash tools/debian13.sh run bash tools/gui_userdata_check.sh
#
# Inside the Debian 13 root (Debian's Blender 4.3, Xvfb): installs the extension zip into a fresh
# user directory (tools/blender_gui_env.sh), starts Blender in a virtual X server and lets the
# script drive the operators from a timer.  Prints one line per check; exits 1 if any failed,
# or if Blender has not quit after GUI_CHECK_TIMEOUT_S seconds (default 1800: the script's own
# waits for the modal solves are 300 s each), when it is stopped, so CI does not wait forever.
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/blender_gui_env.sh
mkdir -p "$WORK/out"
limit="${GUI_CHECK_TIMEOUT_S:-1800}"
rc=0
timeout -k 30 "$limit" xvfb-run -a -s "-screen 0 1600x1000x24" \
  blender --window-geometry 0 0 1600 1000 --no-window-focus \
    --python tools/gui_userdata_check.py -- --repo "$PWD" --out "$WORK/out" --result "$WORK/result.json" \
    > "$WORK/blender.log" 2>&1 || rc=$?
if [ "$rc" = 124 ] || [ "$rc" = 137 ]; then
  grep "userdata_check:" "$WORK/blender.log" || true
  tail -40 "$WORK/blender.log"
  echo "gui_userdata_check: Blender did not finish in $limit s (GUI_CHECK_TIMEOUT_S): stopped" >&2
  exit 1
fi
grep "userdata_check:" "$WORK/blender.log" || { tail -40 "$WORK/blender.log"; exit 1; }
python3 -c "import json,sys; sys.exit(any(not c['ok'] for c in json.load(open(sys.argv[1]))))" "$WORK/result.json"
