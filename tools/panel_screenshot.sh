#!/usr/bin/env bash
# The README's screenshot of the MANIKIN sidebar, taken from a real Blender window.
#
#   bash tools/debian13.sh run bash tools/panel_screenshot.sh [OUT.png] [KEYPOINTS]   # default docs/panel.png
#
# With KEYPOINTS (a keypoint file or FreeMoCap folder, e.g. examples/example_keypoints) the panel's
# Keypoints source solves that instead of the example recording.  $MANIKIN_SHOT_ARGS passes more
# options to tools/panel_screenshot.py (e.g. "--open calibration,output --unit-scale 0.01
# --ui-scale 1.25"); $MANIKIN_SHOT_SIDEBAR (pixels, e.g. 250) narrows the sidebar to that width by
# dragging its left border as a user would (the default: Blender's own width).
# Inside the Debian 13 root (Debian's Blender 4.3, Xvfb, ImageMagick): builds the linux-x64
# extension zip, installs it with Blender's own installer into a fresh user directory, starts
# Blender in a virtual X server, lets tools/panel_screenshot.py solve the bundled example with
# the add-on's operator and open the sidebar, switches the sidebar to the MANIKIN tab as a user
# would (Ctrl+wheel, xdotool), then grabs the screen with ImageMagick's `import`.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-docs/panel.png}"
KEYPOINTS_ARG="${2:+--keypoints $2}"
source tools/blender_gui_env.sh
W=1600; H="${MANIKIN_SHOT_HEIGHT:-1000}"
xvfb-run -a -s "-screen 0 ${W}x${H}x24" bash -c '
  set -euo pipefail
  blender --window-geometry 0 0 '"$W"' '"$H"' --no-window-focus \
      --python tools/panel_screenshot.py -- --example examples/example_recording.csv \
      --ready "'"$WORK"'/ready" --done "'"$WORK"'/done" '"$KEYPOINTS_ARG"' '"${MANIKIN_SHOT_ARGS:-}"' \
      > "'"$WORK"'/blender.log" 2>&1 &
  pid=$!
  for _ in $(seq 1 600); do
    [ -e "'"$WORK"'/ready" ] && break
    kill -0 $pid 2>/dev/null || { cat "'"$WORK"'/blender.log" >&2; exit 1; }
    sleep 0.2
  done
  [ -e "'"$WORK"'/ready" ] || { echo "Blender never got ready" >&2; cat "'"$WORK"'/blender.log" >&2; kill $pid; exit 1; }
  field() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])" "'"$WORK"'/ready" "$1"; }
  xdotool mousemove "$(field x)" "$(field y)"
  for _ in $(seq 1 12); do
    [ "$(field category)" = MANIKIN ] && break
    xdotool keydown ctrl click 5 keyup ctrl
    sleep 0.6
  done
  [ "$(field category)" = MANIKIN ] || { echo "could not switch the sidebar to the MANIKIN tab" >&2; kill $pid; exit 1; }
  if [ -n "'"${MANIKIN_SHOT_SIDEBAR:-}"'" ]; then
    for _ in 1 2 3; do
      w=$(field width); [ "$w" = '"${MANIKIN_SHOT_SIDEBAR:-0}"' ] && break
      x=$(( $(field left) + 8 * $(field scale100) / 100 )); y=$(( $(field y) + 200 )); to=$(( x + w - '"${MANIKIN_SHOT_SIDEBAR:-0}"' ))
      xdotool mousemove $x $y; sleep 0.3; xdotool mousedown 1; sleep 0.3
      for step in 1 2 3 4 5 6 7 8; do xdotool mousemove $(( x + (to - x) * step / 8 )) $y; sleep 0.1; done
      xdotool mouseup 1
      sleep 1.2
    done
    echo "sidebar width: $(field width) px (left edge at x=$(field left))" >&2
  fi
  xdotool mousemove 5 5
  sleep 1
  import -window root "'"$WORK"'/shot.png"
  touch "'"$WORK"'/done"
  wait $pid
'
mkdir -p "$(dirname "$OUT")"
cp "$WORK/shot.png" "$OUT"
echo "wrote $OUT ($(identify -format '%wx%h' "$OUT"))"
