#!/usr/bin/env bash
# GUI picture of the other targets in a real Blender (not run by CI): UDIM tiles, bent normals, Preview on
# Object. From the repository root:
#
#   python scripts/build_extension.py --platform linux-x64
#   ../shared/tools/blender-gui.sh exec 'bash tests/gui/preview.sh'
#
# tests/gui/check_preview.py installs the zip, bakes Suzanne and a ground plane over UDIM tiles 1001
# and 1002 (Bake AO, with UDIM Tiles and Bent Normals on), clicks Preview on Object and shows the
# tiled AO image; this script opens the MC AO tab and takes the screenshots: $OUT/before.png (Material
# Preview before the click) and $OUT/preview.png (after it: docs/preview.png), with
# $OUT/baked.json and $OUT/previewed.json saying what was made.
set -euo pipefail
OUT=${OUT:-/tmp/out/mc_ao_preview}
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

MC_AO_ZIP=$(realpath "$ZIP") MC_AO_GUI_OUT=$OUT \
  blender --factory-startup --window-geometry 0 0 1600 1000 --python tests/gui/check_preview.py \
  >"$OUT/blender.log" 2>&1 &
BLENDER=$!
trap 'kill $BLENDER 2>/dev/null || true' EXIT

wait_for "$OUT/ready.json" 600
read -r TX TTOP < <(python3 -c "import json; d = json.load(open('$OUT/ready.json')); print(d['tabs_x'], d['tabs_top'])")
xdotool mousemove 800 500; sleep 0.3; xdotool key Escape; sleep 1   # the splash screen
for dy in $(seq 8 10 400); do
  [ -f "$OUT/tab.json" ] && break
  xdotool mousemove "$TX" $((TTOP + dy)); sleep 0.2; xdotool click 1; sleep 0.5
done
wait_for "$OUT/tab.json" 5
xdotool mousemove 1560 980; sleep 40   # out of the way; Material Preview compiles its shaders (llvmpipe: slow)
shot before.png
touch "$OUT/before"                     # check_preview.py clicks Preview on Object
wait_for "$OUT/previewed.json" 30
sleep 40
shot preview.png
cat "$OUT/baked.json" "$OUT/previewed.json"
