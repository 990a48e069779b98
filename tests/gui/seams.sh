#!/usr/bin/env bash
# GUI test of Fix Seams in a real Blender (not run by CI): a UV seam of Suzanne in the viewport,
# baked with Fix Seams off and then on, read off the screen on both sides. From the repository root:
#
#   python scripts/build_extension.py --platform linux-x64
#   flock -o /work/notes/gui.lock ../shared/tools/blender-gui.sh exec 'bash tests/gui/seams.sh'
#
# tests/gui/check_seams.py does the work (its docstring says what it reads); this script closes the
# splash screen, waits for its result and fails unless result.json says passed. Screenshots:
# $OUT/before.png, $OUT/after.png (docs/seams-before.png, docs/seams-after.png).
set -euo pipefail
OUT=${OUT:-/tmp/out/mc_ao_seams}
ZIP=${MC_AO_ZIP:-$(ls dist/mc_ao-*-linux_x64.zip | head -n 1)}
rm -rf "$OUT" && mkdir -p "$OUT"

MC_AO_ZIP=$(realpath "$ZIP") MC_AO_GUI_OUT=$OUT MC_AO_REPO=$PWD \
  blender --factory-startup --window-geometry 0 0 1600 1000 --python tests/gui/check_seams.py \
  >"$OUT/blender.log" 2>&1 &
BLENDER=$!
trap 'kill $BLENDER 2>/dev/null || true' EXIT
sleep 8
xdotool mousemove 800 500; sleep 0.3; xdotool key Escape; sleep 0.5; xdotool mousemove 1590 990
shot() { xwd -root -silent | xwdtopnm 2>/dev/null | pnmtopng >"$OUT/$1"; echo "screenshot $OUT/$1"; }
for _ in $(seq 1 900); do
  [ -f "$OUT/result.json" ] && break
  for name in before.png after.png; do
    if [ -f "$OUT/ready_$name.json" ] && [ ! -f "$OUT/shot_$name" ]; then
      sleep 3; shot "$name"; touch "$OUT/shot_$name"
    fi
  done
  if [ -f "$OUT/error.json" ]; then cat "$OUT/error.json" >&2; exit 1; fi
  kill -0 $BLENDER 2>/dev/null || { echo "Blender exited" >&2; tail -20 "$OUT/blender.log" >&2; exit 1; }
  sleep 1
done
cat "$OUT/result.json"
python3 -c "import json, sys; sys.exit(0 if json.load(open('$OUT/result.json'))['passed'] else 1)"
