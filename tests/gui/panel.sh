#!/usr/bin/env bash
# GUI check of the panel's items in a real Blender 4.3 (not run by CI). From the
# repository root, under the GUI lock:
#
#   .venv/bin/python scripts/build_extension.py --platform linux-x64      # the zip with the cp313 wheel
#   flock -o /work/notes/gui.lock ../shared/tools/blender-gui.sh exec 'bash tests/gui/panel.sh'
#
# tests/gui/check_panel.py sets Blender up (props.blend, the sidebar, a free and a pinned Image
# Editor) and answers commands; this script clicks as a hand does and takes screenshots; then
# tests/gui/panel_verdict.py checks the answers and the pixels and writes verdict.json (exit 1 when an
# item fails). Output in $OUT (default /tmp/out/mc_ao_panel, the host's $ROOT/tmp/out/mc_ao_panel).
set -euo pipefail
OUT=${OUT:-/tmp/out/mc_ao_panel}
ZIP=${MC_AO_ZIP:-$(ls dist/mc_ao-*-linux_x64.zip | head -n 1)}
rm -rf "$OUT" && mkdir -p "$OUT"
shot() { sleep 0.8; xwd -root -silent | xwdtopnm 2>/dev/null | pnmtopng >"$OUT/$1.png"; echo "shot $1"; }
wait_for() {  # FILE SECONDS
  for _ in $(seq 1 "$2"); do
    [ -f "$1" ] && return 0
    if [ -f "$OUT/error.json" ]; then cat "$OUT/error.json" >&2; exit 1; fi
    kill -0 $BLENDER 2>/dev/null || { echo "Blender exited" >&2; exit 1; }
    sleep 0.5
  done
  echo "timed out waiting for $1" >&2; return 1
}
N=0
cmd() {  # JSON [NAME]: one command to check_panel.py; its answer is ack_N.json (copied to NAME.json)
  echo "$1" >"$OUT/cmd_$N.json.tmp" && mv "$OUT/cmd_$N.json.tmp" "$OUT/cmd_$N.json"
  wait_for "$OUT/ack_$N.json" 1200
  if [ -n "${2:-}" ]; then cp "$OUT/ack_$N.json" "$OUT/$2.json"; fi
  N=$((N + 1))
}
# Come to the button from elsewhere, as a hand does: Blender refreshes a button's state on motion.
click_bake() { for p in "200 700" "$((X - 150)) $((Y + 60))" "$X $((Y + 30))" "$X $((Y - 4))" "$X $Y"; do
                 xdotool mousemove $p; sleep 0.2; done; sleep 0.5; xdotool click 1; }
# Bake AO clicked and waited for (NAME.json); clicked again, up to twice more, where the click did not
# start a bake (Blender 4.3 can keep drawing a button that was greyed out under the pointer as such).
bake() {  # NAME [SECONDS]
  for try in 1 2 3; do
    click_bake; sleep 1
    cmd "{\"do\": \"wait_bake\", \"seconds\": ${2:-600}}" "$1"
    if python3 -c "import json, sys; sys.exit(0 if json.load(open('$OUT/$1.json'))['seen_running'] else 1)"; then
      echo "$1: baked (click $try)"; return 0
    fi
    echo "$1: the click did not start a bake; again"
  done
  return 1
}
# The pointer away from the sidebar, in steps as a hand moves it (Blender closes a button's tooltip
# and ends its hover on the motion it sees): no hover highlight in the screenshots.
rest() { for p in "$X $((Y + 30))" "$((X - 150)) $((Y + 60))" "300 600" "300 900"; do xdotool mousemove $p; sleep 0.15; done; sleep 0.3; }

MC_AO_ZIP=$(realpath "$ZIP") MC_AO_GUI_OUT=$OUT \
  blender --factory-startup --window-geometry 0 0 1600 1000 --python tests/gui/check_panel.py \
  >"$OUT/blender.log" 2>&1 &
BLENDER=$!
trap 'kill $BLENDER 2>/dev/null || true' EXIT

wait_for "$OUT/ready.json" 360
read -r X Y TX TTOP < <(python3 -c "import json; d = json.load(open('$OUT/ready.json')); print(d['x'], d['y'], d['tabs_x'], d['tabs_top'])")
xdotool mousemove 800 500; sleep 0.3; xdotool key Escape; sleep 1   # the splash screen
for dy in $(seq 8 10 400); do
  [ -f "$OUT/tab.json" ] && break
  xdotool mousemove "$TX" $((TTOP + dy)); sleep 0.2; xdotool click 1; sleep 0.5
done
wait_for "$OUT/tab.json" 10
rest
cmd '{"do": "state"}' start
shot start

# 1. The layout stays still over a matrix of settings (panel_verdict.py: the sub-panels' headers in
#    the same rows in every shot). Each state from the defaults.
DEFAULTS='"target": "IMAGE_TEXTURES", "quantity": ["AO"], "channel": "NONE", "into": "", "only_local": false, "ground": "OFF", "use_udim": false, "bent_normals": false, "denoise": false, "target_error": 0.0, "image_name": "", "use_selected_to_active": false, "use_cage": false'
i=0
for state in '' \
    '"quantity": ["AO", "THICKNESS"]' \
    '"channel": "R", "into": "Crate_ORM"' \
    '"channel": "R", "into": ""' \
    '"target": "VERTEX_COLORS"' \
    '"bent_normals": true, "use_udim": true' \
    '"only_local": true, "ground": "AUTO"' \
    '"ground": "HEIGHT", "target_error": 0.01, "denoise": true' \
    '"use_selected_to_active": true, "use_cage": true' \
    '"image_name": "A_much_longer_image_name_{object}_with_more_words_than_a_row_holds"'; do
  cmd "{\"do\": \"set\", \"values\": {$DEFAULTS${state:+, $state}}}" "still_$i"
  shot "still_$i"
  i=$((i + 1))
done
cmd "{\"do\": \"set\", \"values\": {$DEFAULTS}}"
# the selection's reason (a light would be skipped; two objects into one image is refused) in the same rows
cmd '{"do": "select", "objects": ["Crate", "Barrel"], "active": "Barrel"}'
cmd '{"do": "set", "values": {"image_name": "Shared"}}' greyed
rest; shot "still_$i"; cp "$OUT/still_$i.png" "$OUT/greyed.png"
# 2. Bake AO greyed out with the reason: a click does nothing.
click_bake; sleep 3
# the greyed button's tooltip (with its reason) opened under the resting pointer: Esc closes it, as a
# hand moving away does (xdotool's jumps do not always reach it)
xdotool key Escape; sleep 0.5; rest
cmd '{"do": "state"}' greyed_clicked
cmd '{"do": "set", "values": {"image_name": ""}}' enabled
rest; shot enabled

# 3. A greyed-out Into does not count: Channel Red into Crate_ORM, back to Own Image, Bake AO.
cmd '{"do": "select", "objects": ["Crate"], "active": "Crate"}'
cmd '{"do": "set", "values": {"channel": "R", "into": "Crate_ORM"}}'
cmd '{"do": "set", "values": {"channel": "NONE"}}' into_greyed
bake into_greyed_baked
rest; shot into_greyed_baked

# 4. The image being baked in the free Image Editor while it fills in (during_*.json), not in the
#    pinned one; the summary names the channel-packing target and what occluded the bake.
cmd '{"do": "editor_image", "image": "Crate_ORM"}'
cmd '{"do": "set", "values": {"channel": "R", "into": "Crate_ORM", "samples": 256}}'
click_bake; sleep 1
# the screenshot once the free editor shows the image being baked (check_panel.py's during_N.json)
echo '{"do": "wait_bake", "seconds": 900}' >"$OUT/cmd_$N.json.tmp" && mv "$OUT/cmd_$N.json.tmp" "$OUT/cmd_$N.json"
for _ in $(seq 1 600); do
  if grep -qs '"free_editor": "Crate_AO"' "$OUT/during_$N.json"; then sleep 2; rest; shot filling; break; fi
  [ -f "$OUT/ack_$N.json" ] && break
  sleep 0.5
done
wait_for "$OUT/ack_$N.json" 1200; cp "$OUT/ack_$N.json" "$OUT/channel_baked.json"; N=$((N + 1))
rest; shot channel_baked
cmd '{"do": "set", "values": {"channel": "NONE", "samples": 32}}'

# 5. The estimate prices the settings: Denoise, a second quantity.
cmd '{"do": "set", "values": {"denoise": false}}' estimate_plain
cmd '{"do": "set", "values": {"denoise": true}}' estimate_denoise
cmd '{"do": "set", "values": {"denoise": false, "quantity": ["AO", "THICKNESS"]}}' estimate_two
cmd '{"do": "set", "values": {"quantity": ["AO"]}}'

# 6. Only Local and the ground: the Occlusion line says the ground counts; a bake's summary too.
cmd '{"do": "set", "values": {"only_local": true, "ground": "AUTO"}}' only_local_ground
rest; shot only_local_ground
# the Occlusion section, scrolled into view (wheel over the sidebar), then back
xdotool mousemove "$X" $((Y + 300)); sleep 0.3
for _ in $(seq 1 12); do xdotool click 5; sleep 0.1; done
xdotool mousemove 300 900; shot occlusion
xdotool mousemove "$X" $((Y + 300)); sleep 0.3
for _ in $(seq 1 12); do xdotool click 4; sleep 0.1; done
rest
bake only_local_baked
cmd '{"do": "set", "values": {"only_local": false, "ground": "OFF"}}'

# 7. A free Image Editor that paints keeps its image: Bake AO leaves it alone.
cmd '{"do": "editor_image", "image": "Crate_ORM"}'
cmd '{"do": "editor_mode", "mode": "PAINT"}'
cmd '{"do": "set", "values": {"image_name": "{object}_Painted"}}'
bake painting_baked
cmd '{"do": "editor_mode", "mode": "VIEW"}'

python3 tests/gui/panel_verdict.py "$OUT"
