#!/usr/bin/env bash
# GUI check that nothing baked is lost, in a real Blender (not run by CI). From the repository root:
#
#   python scripts/build_extension.py --platform linux-x64
#   ../shared/tools/blender-gui.sh exec 'bash tests/gui/trust.sh'
#
# Steps (tests/gui/check_trust.py sets up the scene and checks the image after each):
#   1. Bake AO into an existing file image of another size, painted after loading; Esc mid-bake (the
#      bake is held after its first tile until Esc, so Esc never comes too late on a fast machine).
#      cancelled.json: is the image as before (size and painted pixels)?  shot: cancelled.png
#   2. Shift-D, Esc (a duplicate: an unrelated undo step), Ctrl-Z.
#      undo_after_cancel.json: still as before?
#   3. Bake AO to the end (a UV-less mesh is selected too: a warning before the summary).
#      done.json; shot: done.png (the panel's last-bake line; the reports in an Info editor; the status bar)
#   4. Shift-D, Esc, Ctrl-Z. undo_after_bake.json: still the bake?
#   5. Select only the mesh without UVs. shot: no_uv.png (the panel's reason, at the default width)
# Output in $OUT (default /tmp/out/mc_ao_trust, the host's $ROOT/tmp/out/mc_ao_trust).
set -euo pipefail
OUT=${OUT:-/tmp/out/mc_ao_trust}
ZIP=${MC_AO_ZIP:-$(ls dist/mc_ao-*-linux_x64.zip | head -n 1)}
rm -rf "$OUT" && mkdir -p "$OUT"
shot() { xwd -root -silent | xwdtopnm 2>/dev/null | pnmtopng >"$OUT/$1"; echo "screenshot $OUT/$1"; }
wait_for() {  # FILE SECONDS
  for _ in $(seq 1 "$2"); do
    [ -f "$1" ] && return 0
    if [ -f "$OUT/error.json" ]; then cat "$OUT/error.json" >&2; exit 1; fi
    kill -0 $BLENDER 2>/dev/null || { echo "Blender exited" >&2; exit 1; }
    sleep 1
  done
  echo "timed out waiting for $1" >&2; return 1
}
click() { xdotool mousemove 200 600; sleep 0.3; xdotool mousemove "$X" "$Y"; sleep 0.5; xdotool click 1; }
# An unrelated undo step and its undo, with the pointer over the 3D Viewport, as a hand does it.
duplicate_and_undo() {  # N: dupN.json lists the objects with the duplicate, before the Ctrl-Z
  xdotool mousemove "$VX" "$VY"; sleep 0.5
  xdotool key shift+d; sleep 0.7; xdotool key Escape; sleep 1
  touch "$OUT/dup$1"; wait_for "$OUT/dup$1.json" 10
  xdotool key ctrl+z; sleep 2
}

MC_AO_ZIP=$(realpath "$ZIP") MC_AO_GUI_OUT=$OUT \
  blender --factory-startup --window-geometry 0 0 1600 1000 --python tests/gui/check_trust.py \
  >"$OUT/blender.log" 2>&1 &
BLENDER=$!
trap 'kill $BLENDER 2>/dev/null || true' EXIT

wait_for "$OUT/ready.json" 180
read -r X Y TX TTOP VX VY < <(python3 -c "import json; d = json.load(open('$OUT/ready.json')); print(d['x'], d['y'], d['tabs_x'], d['tabs_top'], d['view_x'], d['view_y'])")
xdotool mousemove 800 500; sleep 0.3; xdotool key Escape; sleep 1   # the splash screen
# The MC AO tab: click down the sidebar's tab strip until check_trust.py sees it active (tab.json).
for dy in $(seq 8 10 400); do
  [ -f "$OUT/tab.json" ] && break
  xdotool mousemove "$TX" $((TTOP + dy)); sleep 0.2; xdotool click 1; sleep 0.5
done
wait_for "$OUT/tab.json" 5
sleep 1; shot before.png

click; wait_for "$OUT/held.json" 120; sleep 1; shot during_first.png   # held after its first tile
xdotool key Escape
wait_for "$OUT/cancelled.json" 120; sleep 1; shot cancelled.png

duplicate_and_undo 1; touch "$OUT/undone1"
wait_for "$OUT/undo_after_cancel.json" 30; shot undo_after_cancel.png

click; sleep 1
wait_for "$OUT/done.json" 900; sleep 3; shot done.png

duplicate_and_undo 2; touch "$OUT/undone2"
wait_for "$OUT/undo_after_bake.json" 30; shot undo_after_bake.png

touch "$OUT/select_no_uv"; wait_for "$OUT/no_uv.json" 10; sleep 1
xdotool mousemove "$X" "$((Y + 40))"; sleep 1; shot no_uv.png
for f in cancelled dup1 undo_after_cancel done dup2 undo_after_bake; do echo "== $f"; cat "$OUT/$f.json"; echo; done
grep -E '^\[check_trust\]|Error|Traceback|Info:|Warning' "$OUT/blender.log" || true
