#!/usr/bin/env bash
# GUI check of atlases in a real Blender (not run by CI). From the repository root:
#
#   python scripts/build_extension.py --platform linux-x64
#   flock /work/notes/gui.lock ../shared/tools/blender-gui.sh exec 'bash tests/gui/atlas.sh'
#
# tests/gui/check_atlas.py sets up a floor under the startup cube, their UVs in the two halves of one
# UV square, one material showing the image Atlas (an existing 256 x 128 8-bit sRGB image of grey),
# Images set to One for All with a Size of 512; both selected.
#   1. Bake AO: done1.json (the image: size, depth, colour space, the objects' texels); shot: one.png
#   2. The floor alone, moved: Bake AO again: done2.json; shot: again.png
# Checked here: both bakes keep the image's 256 x 128, 8-bit, sRGB; the second keeps the cube's texels
# bit for bit and the grey where neither object reaches, and changes the floor's. Exit 1 otherwise.
# Output in $OUT (default /tmp/out/mc_ao_atlas, the host's $ROOT/tmp/out/mc_ao_atlas).
set -euo pipefail
OUT=${OUT:-/tmp/out/mc_ao_atlas}
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

MC_AO_ZIP=$(realpath "$ZIP") MC_AO_GUI_OUT=$OUT \
  blender --factory-startup --window-geometry 0 0 1600 1000 --python tests/gui/check_atlas.py \
  >"$OUT/blender.log" 2>&1 &
BLENDER=$!
trap 'kill $BLENDER 2>/dev/null || true' EXIT

wait_for "$OUT/ready.json" 180
read -r X Y TX TTOP < <(python3 -c "import json; d = json.load(open('$OUT/ready.json')); print(d['x'], d['y'], d['tabs_x'], d['tabs_top'])")
xdotool mousemove 800 500; sleep 0.3; xdotool key Escape; sleep 1
for dy in $(seq 8 10 400); do
  [ -f "$OUT/tab.json" ] && break
  xdotool mousemove "$TX" $((TTOP + dy)); sleep 0.2; xdotool click 1; sleep 0.5
done
wait_for "$OUT/tab.json" 5
sleep 1
shot before.png

click
wait_for "$OUT/done1.json" 600
wait_for "$OUT/selected.json" 10
sleep 1
shot one.png
click
wait_for "$OUT/done2.json" 600
sleep 1
shot again.png
grep -E '^\[check_atlas\]|Error|Traceback|Info:|Warning' "$OUT/blender.log" || true
python3 - "$OUT" <<'PY'
import json, sys
out = sys.argv[1]
one, two = (json.load(open(f"{out}/done{k}.json")) for k in (1, 2))
checks = {
    "the image keeps 256 x 128, 8-bit, sRGB": all(d["size"] == [256, 128] and not d["float"] and d["colorspace"] == "sRGB"
                                                  for d in (one, two)),
    "both objects in one image": one["names"] == ["Cube", "Floor"] or sorted(one["names"]) == ["Cube", "Floor"],
    "the cube's texels kept bit for bit": one["cube_digest"] == two["cube_digest"] and one["cube_texels"] > 0,
    "the floor's texels baked again": one["floor_digest"] != two["floor_digest"] and two["floor_texels"] > 0,
    "the grey kept where neither reaches": one["grey_texels"] == two["grey_texels"] > 0,
}
for what, ok in checks.items():
    print(("ok    " if ok else "FAIL  ") + what)
sys.exit(0 if all(checks.values()) else 1)
PY
