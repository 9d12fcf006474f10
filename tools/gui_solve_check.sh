#!/usr/bin/env bash
# The solve operators in a real Blender window, as a user's clicks and keys run them.
#
#   bash tools/debian13.sh run bash tools/gui_solve_check.sh [SHOT.png]
#
# Inside the Debian 13 root (Debian's Blender 4.3, Xvfb, xdotool): installs the extension zip
# into a fresh user directory (tools/blender_gui_env.sh), writes three takes (the bundled example
# and two 4.7-minute takes made of it), starts Blender in a virtual X server and lets
# tools/gui_solve_check.py invoke Solve Full Body (modal, in Blender's event loop) and Solve
# Several Files twice.  When that script says a file browser waits, this one selects every file
# (A) and confirms (Return) with xdotool; when it says so, it presses Esc.  Exits 0 when every
# check passed; prints the checks either way.  With SHOT.png, also saves a screenshot of the
# window while Solve Several Files solves its third take (the status bar: which file, how far).
# Blender (and this script's watch of it) is stopped, and the check fails, after
# GUI_CHECK_TIMEOUT_S seconds (default 1800), so CI does not wait forever on a hung window.
set -euo pipefail
cd "$(dirname "$0")/.."
source tools/blender_gui_env.sh
mkdir -p "$WORK/takes"
python - "$WORK/takes" <<'PY'
import shutil, sys
import numpy as np
from blender_manikin.core.formats import load_recording
from blender_manikin.core.io_csv import write_csv
from blender_manikin.core.recording import Recording, TrackerStream
out = sys.argv[1]
example = "examples/example_recording.csv"
shutil.copy(example, f"{out}/a_example.csv")
rec = load_recording(example)
span = max(s.time[-1] for s in rec.streams.values()) - min(s.time[0] for s in rec.streams.values()) + 0.1
streams = {d: TrackerStream(d, np.concatenate([s.time + k * span for k in range(40)]), np.tile(s.pos, (40, 1)),
                            np.tile(s.quat, (40, 1)), None if s.valid is None else np.tile(s.valid, 40))
           for d, s in rec.streams.items()}
for name in ("b_long.csv", "c_long.csv"):
    write_csv(f"{out}/{name}", Recording(streams=streams, source=name, metadata=dict(rec.metadata)),
              axes="openxr", units="m")
PY
SHOT="${1:+$(realpath -m "$1")}"
export WORK SHOT
limit="${GUI_CHECK_TIMEOUT_S:-1800}"
rc=0
timeout -k 30 "$limit" xvfb-run -a -s "-screen 0 1600x1000x24" bash -c '
  set -uo pipefail
  blender --window-geometry 0 0 1600 1000 --no-window-focus --python-exit-code 1 \
      --python tools/gui_solve_check.py -- --takes "$WORK/takes/" --state "$WORK/state.json" \
      > "$WORK/blender.log" 2>&1 &
  pid=$!
  field() { python3 -c "import json,sys; print(json.load(open(sys.argv[1])).get(sys.argv[2], \"\"))" \
            "$WORK/state.json" "$1" 2>/dev/null || true; }
  confirmed=0; escaped=0
  while kill -0 $pid 2>/dev/null; do
    phase=$(field phase); step=$(field step)
    if [ "$phase" = browser ] && [ "$step" != "$confirmed" ]; then
      tries=$((${tries:-0} + 1))
      sleep $((tries + 1))                          # the file browser drawn and listing the folder
      fb=$(xdotool search --name "File View" | head -1 || true)
      [ -n "$fb" ] && xdotool windowfocus --sync "$fb"
      xdotool mousemove 800 400; sleep 0.3
      xdotool key a; sleep 0.5; xdotool key Return
      confirmed=$step
    elif [ -n "$SHOT" ] && [ "$phase" = solving ] && [ "$step" = 1 ] && [ "$(field solved)" = 2 ] \
         && [ ! -e "$SHOT" ]; then
      import -window root "$SHOT"
    elif [ "$phase" = escape ] && [ $escaped = 0 ]; then
      main=$(xdotool search --name "Blender" | head -1 || true)
      [ -n "$main" ] && xdotool windowfocus "$main"
      xdotool mousemove 800 500 key Escape
      escaped=1
    fi
    sleep 0.1
  done
  wait $pid; rc=$?
  grep -E "^gui_solve_check|Traceback|Error" "$WORK/blender.log" || tail -30 "$WORK/blender.log"
  python3 -c "import json,sys; [print(\"  \" + c) for c in json.load(open(sys.argv[1]))[\"checks\"]]" \
      "$WORK/state.json" 2>/dev/null || true
  exit $rc
' || rc=$?
if [ "$rc" = 124 ] || [ "$rc" = 137 ]; then
  tail -40 "$WORK/blender.log" || true
  echo "gui_solve_check: Blender did not finish in $limit s (GUI_CHECK_TIMEOUT_S): stopped" >&2
fi
exit "$rc"
