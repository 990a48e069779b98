#!/usr/bin/env bash
# Screenshots of the occluder settings in the real Blender (not run by CI). From the repository root:
#
#   ../shared/tools/blender-gui.sh setup      # once
#   ../shared/tools/blender-gui.sh exec 'bash tests/gui/occluders.sh start'
#   ../shared/tools/blender-gui.sh exec 'bash tests/gui/occluders.sh shot NAME'      # $OUT/NAME.png
#   ../shared/tools/blender-gui.sh exec 'bash tests/gui/occluders.sh click X Y'      # a click, as a hand does
#   ../shared/tools/blender-gui.sh exec 'bash tests/gui/occluders.sh scroll N X Y'   # wheel N steps down over X Y
#   ../shared/tools/blender-gui.sh exec 'bash tests/gui/occluders.sh stop'
#
# start runs Blender with tests/gui/occluders_panel.py (the checkout's add-on, a floor under boxes in
# collections, the new settings set) in the background, closes the splash screen and clicks down the
# sidebar's tabs until it shows MC AO. $OUT/state.json follows the settings as clicks change them.
set -euo pipefail
OUT=${OUT:-/tmp/out/mc_ao_occluders}
wait_for() {
  for _ in $(seq 1 "$2"); do
    [ -f "$1" ] && return 0
    if [ -f "$OUT/error.json" ]; then cat "$OUT/error.json" >&2; exit 1; fi
    sleep 1
  done
  echo "timed out waiting for $1" >&2; return 1
}
case "$1" in
start)
  rm -rf "$OUT" && mkdir -p "$OUT"
  MC_AO_GUI_OUT=$OUT setsid nohup blender --factory-startup --window-geometry 0 0 1600 1000 \
    --python tests/gui/occluders_panel.py >"$OUT/blender.log" 2>&1 &
  echo $! >"$OUT/blender.pid"
  wait_for "$OUT/ready.json" 180
  read -r TX TTOP < <(python3 -c "import json; d = json.load(open('$OUT/ready.json')); print(d['tabs_x'], d['tabs_top'])")
  xdotool mousemove 800 500; sleep 0.3; xdotool key Escape; sleep 1
  for dy in $(seq 8 10 400); do
    [ -f "$OUT/tab.json" ] && break
    xdotool mousemove "$TX" $((TTOP + dy)); sleep 0.2; xdotool click 1; sleep 0.5
  done
  wait_for "$OUT/tab.json" 5
  cat "$OUT/ready.json"
  ;;
shot)
  sleep 1; xwd -root -silent | xwdtopnm 2>/dev/null | pnmtopng >"$OUT/$2.png"; echo "$OUT/$2.png"
  ;;
click)
  xdotool mousemove 200 600; sleep 0.3; xdotool mousemove "$2" "$3"; sleep 0.5; xdotool click 1; sleep 1
  ;;
scroll)
  xdotool mousemove "$3" "$4"; sleep 0.3
  for _ in $(seq 1 "$2"); do xdotool click 5; sleep 0.1; done
  ;;
stop)
  kill "$(cat "$OUT/blender.pid")" 2>/dev/null || true
  ;;
esac
