#!/usr/bin/env bash
# GUI check of undo after two bakes into an existing image, in a real Blender (not run by CI; Blender's
# undo takes another path in background mode). From the repository root:
#
#   python scripts/build_extension.py --platform linux-x64
#   flock -o /work/notes/gui.lock ../shared/tools/blender-gui.sh exec 'bash tests/gui/undo.sh packed'
#   flock -o /work/notes/gui.lock ../shared/tools/blender-gui.sh exec 'bash tests/gui/undo.sh file'
#
# tests/gui/check_undo.py sets up the scene; this script clicks Bake AO twice (the second after a
# setting changed), presses Ctrl-Z, then Ctrl-Shift-Z, over the 3D Viewport, and fails unless the image
# holds the first bake's pixels after Ctrl-Z and the second's after Ctrl-Shift-Z (undo.json, redo.json,
# screenshots in $OUT, default /tmp/out/mc_ao_undo_MODE).
set -euo pipefail
MODE=${1:-packed}
OUT=${OUT:-/tmp/out/mc_ao_undo_$MODE}
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

MC_AO_ZIP=$(realpath "$ZIP") MC_AO_GUI_OUT=$OUT MC_AO_UNDO_MODE=$MODE \
  blender --factory-startup --window-geometry 0 0 1600 1000 --python tests/gui/check_undo.py \
  >"$OUT/blender.log" 2>&1 &
BLENDER=$!
trap 'kill $BLENDER 2>/dev/null || true' EXIT

wait_for "$OUT/ready.json" 180
read -r X Y TX TTOP VX VY < <(python3 -c "import json; d = json.load(open('$OUT/ready.json')); print(d['x'], d['y'], d['tabs_x'], d['tabs_top'], d['view_x'], d['view_y'])")
xdotool mousemove 800 500; sleep 0.3; xdotool key Escape; sleep 1   # the splash screen
for dy in $(seq 8 10 400); do
  [ -f "$OUT/tab.json" ] && break
  xdotool mousemove "$TX" $((TTOP + dy)); sleep 0.2; xdotool click 1; sleep 0.5
done
wait_for "$OUT/tab.json" 5

click; wait_for "$OUT/done1.json" 600; wait_for "$OUT/changed.json" 10; sleep 1; shot first.png
click; wait_for "$OUT/done2.json" 600; sleep 1; shot second.png
xdotool mousemove "$VX" "$VY"; sleep 0.5
xdotool key ctrl+z; sleep 2; touch "$OUT/undone"; wait_for "$OUT/undo.json" 30; sleep 1; shot undo.png
xdotool mousemove "$VX" "$VY"; sleep 0.5
xdotool key ctrl+shift+z; sleep 2; touch "$OUT/redone"; wait_for "$OUT/redo.json" 30; sleep 1; shot redo.png
for f in done1 done2 undo redo; do echo "== $f"; cat "$OUT/$f.json"; echo; done
grep -E '^\[check_undo\]|Error|Traceback' "$OUT/blender.log" | grep -v '^\[check_undo\] \(done\|undo\|redo\)' || true
python3 - "$OUT" <<'PY'
import json, sys
out = sys.argv[1]
d1, d2 = (json.load(open(f"{out}/{n}.json")) for n in ("done1", "done2"))
undo, redo = (json.load(open(f"{out}/{n}.json")) for n in ("undo", "redo"))
problems = []
if not d1["changed"] or not d2["differs"]:
    problems.append("the two bakes did not give two different images")
if not undo["as_first_bake"]:
    problems.append(f"after Ctrl-Z the image is not the first bake's: {undo['now']}")
if not redo["as_second_bake"]:
    problems.append(f"after Ctrl-Shift-Z the image is not the second bake's: {redo['now']}")
print("UNDO CHECK:", "FAILED: " + "; ".join(problems) if problems else "passed")
sys.exit(1 if problems else 0)
PY
