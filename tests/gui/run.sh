#!/usr/bin/env bash
# GUI test of the extension in a real Blender (not run by CI). From the repository root:
#
#   python scripts/build_extension.py --platform linux-x64      # the zip with the cp313 wheel
#   ../shared/tools/blender-gui.sh setup                        # once
#   ../shared/tools/blender-gui.sh exec 'bash tests/gui/run.sh'
#
# Inside the chroot it starts Blender with tests/gui/click_bake.py (which installs the zip and sets
# up the scene), clicks Bake AO with xdotool, and takes screenshots into $OUT (default
# /tmp/out/mc_ao_gui, the host's $ROOT/tmp/out/mc_ao_gui): before.png, during.png, after.png,
# then clicks Bake AO again, presses Esc, and takes cancelled.png. Look at them.
set -euo pipefail
OUT=${OUT:-/tmp/out/mc_ao_gui}
ZIP=${MC_AO_ZIP:-$(ls dist/mc_ao-*-linux_x64.zip | head -n 1)}
rm -rf "$OUT" && mkdir -p "$OUT"
shot() { xwd -root -silent | xwdtopnm 2>/dev/null | pnmtopng >"$OUT/$1"; echo "screenshot $OUT/$1"; }
wait_for() {  # FILE SECONDS; stops early on Blender's error.json
  for _ in $(seq 1 "$2"); do
    [ -f "$1" ] && return 0
    if [ -f "$OUT/error.json" ]; then cat "$OUT/error.json" >&2; exit 1; fi
    kill -0 $BLENDER 2>/dev/null || { echo "Blender exited" >&2; exit 1; }
    sleep 1
  done
  echo "timed out waiting for $1" >&2; return 1
}
# Come to the button from elsewhere, as a hand does: Blender refreshes a button's state on motion.
click() { xdotool mousemove 200 600; sleep 0.3; xdotool mousemove "$X" "$Y"; sleep 0.5; xdotool click 1; }

MC_AO_ZIP=$(realpath "$ZIP") MC_AO_GUI_OUT=$OUT \
  blender --factory-startup --window-geometry 0 0 1600 1000 --python tests/gui/click_bake.py \
  >"$OUT/blender.log" 2>&1 &
BLENDER=$!
trap 'kill $BLENDER 2>/dev/null || true' EXIT

wait_for "$OUT/ready.json" 180
read -r X Y TX TTOP < <(python3 -c "import json; d = json.load(open('$OUT/ready.json')); print(d['x'], d['y'], d['tabs_x'], d['tabs_top'])")
echo "Bake AO button at $X $Y"
# The factory startup opens the splash screen; Esc closes it.
xdotool mousemove 800 500; sleep 0.3; xdotool key Escape; sleep 1
# Click down the sidebar's tab strip until the MC AO tab is the active one.
for dy in $(seq 8 10 400); do
  [ -f "$OUT/tab.json" ] && break
  xdotool mousemove "$TX" $((TTOP + dy)); sleep 0.2; xdotool click 1; sleep 0.5
done
wait_for "$OUT/tab.json" 5
sleep 1
shot before.png

click
sleep 3
shot during.png
wait_for "$OUT/done.json" 600
sleep 1
shot after.png

click
sleep 3
xdotool key Escape
wait_for "$OUT/cancelled.json" 120
sleep 1
shot cancelled.png
cat "$OUT/done.json" "$OUT/cancelled.json"
grep -E '^\[click_bake\]|Error|Traceback|Info:|Warning' "$OUT/blender.log" || true
