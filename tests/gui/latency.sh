#!/usr/bin/env bash
# UI latency of the real Blender while Bake AO runs (not run by CI). From the repository root:
#
#   python scripts/build_extension.py --platform linux-x64      # the zip with the cp313 wheel
#   ../shared/tools/blender-gui.sh setup                        # once
#   ../shared/tools/blender-gui.sh exec 'bash tests/gui/latency.sh'
#
# Inside the chroot it starts Blender on sample_scenes/suzanne.blend with tests/gui/ui_latency.py,
# which installs the zip, checks worker processes with the installed core, and measures a 10 ms
# bpy.app.timers callback while idle, while Bake AO bakes on threads and while it bakes in worker
# processes. Results in $OUT (default /tmp/out/mc_ao_latency, the host's $ROOT/tmp/out/mc_ao_latency):
# table.txt, results.json, direct.json, intervals_*.npy, screenshots. MC_AO_LAT_* variables
# (see ui_latency.py) choose the resolution, samples, workers and modes.
set -euo pipefail
OUT=${OUT:-/tmp/out/mc_ao_latency}
ZIP=${MC_AO_ZIP:-$(ls dist/mc_ao-*-linux_x64.zip | head -n 1)}
LIMIT=${MC_AO_LAT_LIMIT:-900}
rm -rf "$OUT" && mkdir -p "$OUT"

MC_AO_ZIP=$(realpath "$ZIP") MC_AO_LAT_OUT=$OUT \
  blender --factory-startup --window-geometry 0 0 1600 1000 sample_scenes/suzanne.blend \
  --python tests/gui/ui_latency.py >"$OUT/blender.log" 2>&1 &
BLENDER=$!
trap 'kill $BLENDER 2>/dev/null || true' EXIT

for _ in $(seq 1 "$LIMIT"); do
  if [ -f "$OUT/ready.json" ] && [ ! -f "$OUT/go" ]; then
    # The factory startup opens the splash screen; Esc closes it.
    sleep 1; xdotool mousemove 800 500; sleep 0.3; xdotool key Escape; sleep 1; touch "$OUT/go"
  fi
  if [ -f "$OUT/error.json" ]; then cat "$OUT/error.json" >&2; exit 1; fi
  [ -f "$OUT/done.json" ] && break
  kill -0 $BLENDER 2>/dev/null || { echo "Blender exited before the end" >&2; tail -30 "$OUT/blender.log" >&2; exit 1; }
  sleep 1
done
[ -f "$OUT/done.json" ] || { echo "timed out after $LIMIT s" >&2; exit 1; }
for _ in $(seq 1 20); do kill -0 $BLENDER 2>/dev/null || break; sleep 1; done
cat "$OUT/table.txt"
python3 -c "import json; d = json.load(open('$OUT/direct.json')); print('direct workers check:', json.dumps(d, indent=1))"
grep -E 'Error|Traceback|Warning' "$OUT/blender.log" || true
