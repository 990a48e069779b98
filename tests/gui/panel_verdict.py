"""The verdict of tests/gui/panel.sh: each panel item, checked on what the real Blender
answered (check_panel.py's JSON files) and on the screenshots' pixels; writes verdict.json and the
pictures for docs/ (docs_*.png), and exits with 1 when an item fails.

    python3 tests/gui/panel_verdict.py OUT

Runs inside the GUI chroot (python3 with numpy; netpbm reads and writes the PNG files).
"""

import glob
import json
import os
import re
import subprocess
import sys

import numpy as np

OUT = sys.argv[1]
results = {}


def load(name):
    with open(os.path.join(OUT, name + ".json")) as fh:
        return json.load(fh)


def pixels(name):
    """A screenshot as an (H, W, 3) uint8 array (PNG -> binary PPM through netpbm)."""
    ppm = subprocess.run(["pngtopnm", os.path.join(OUT, name + ".png")], capture_output=True, check=True).stdout
    head = re.match(rb"P6\s+(\d+)\s+(\d+)\s+(\d+)\s", ppm)
    w, h = int(head[1]), int(head[2])
    return np.frombuffer(ppm, np.uint8, w * h * 3, head.end()).reshape(h, w, 3)


def save(array, name):
    """``array`` (H, W, 3) as OUT/name.png."""
    h, w, _ = array.shape
    ppm = b"P6\n%d %d\n255\n" % (w, h) + np.ascontiguousarray(array, np.uint8).tobytes()
    png = subprocess.run(["pnmtopng"], input=ppm, capture_output=True, check=True).stdout
    with open(os.path.join(OUT, name + ".png"), "wb") as fh:
        fh.write(png)


def check(item, ok, detail):
    results[item] = {"ok": bool(ok), "detail": detail}
    print(("PASS " if ok else "FAIL ") + item + ": " + str(detail))


ready = load("ready")
sx, stop, sw, sh = ready["sidebar"]


def boundaries(image):
    """The rows where the colour changes down a column of the sidebar left of every label and icon:
    the edges of its panels and sub-panel headers. A layout that moves moves them."""
    col = image[stop + 2:stop + sh - 2, sx + 8].astype(int)
    return [int(y) + stop + 3 for y in np.nonzero(np.any(np.diff(col, axis=0) != 0, axis=1))[0]]


# 1. The layout stays still: the same panel edges in every shot over the matrix of settings (each
#    still_N: a setting changed, a long image name, a reason instead of the targets), while a bake
#    runs and after it.
stills = sorted(os.path.basename(p)[:-4] for p in glob.glob(os.path.join(OUT, "still_*.png")))
shots = stills + ["enabled", "filling", "channel_baked", "only_local_ground"]
edges = {name: boundaries(pixels(name)) for name in shots if os.path.exists(os.path.join(OUT, name + ".png"))}
reference = edges[stills[0]]
moved = {name: e for name, e in edges.items() if e != reference}
check("layout still over the settings matrix", not moved and len(reference) >= 4 and len(edges) >= 12,
      {"shots": len(edges), "edges": reference, "moved": moved})

# 2. Bake AO greyed out with the reason (cheap checks), and a click on it does nothing.
greyed, clicked = load("greyed"), load("greyed_clicked")
button = lambda image: image[ready["y"] - 8:ready["y"] + 8, sx + 20:sx + sw - 40].astype(int).sum(axis=2)
# Blender draws a disabled button dimmer, its face and its text: (median, 99.9th percentile) of R+G+B
bright_greyed, bright_enabled = ([float(v) for v in np.percentile(button(pixels(n)), [50, 99.9])]
                                 for n in ("greyed", "enabled"))
check("button greyed with the reason", not greyed["poll"] and "would both bake into image 'Shared'" in (greyed["reason"] or "")
      and clicked["last"] is None and not clicked["running"] and load("enabled")["poll"]
      and bright_enabled[0] > bright_greyed[0] + 12 and bright_enabled[1] > bright_greyed[1] + 20,
      {"reason": greyed["reason"], "last after the click": clicked["last"],
       "button face and text brightness (median, 99.9th percentile of R+G+B) greyed / enabled":
           [bright_greyed, bright_enabled]})

# 3. A greyed-out setting does not count: Into still set, Channel back to Own Image: the bake runs.
baked = load("into_greyed_baked")
check("greyed-out Into does not count", baked["seen_running"] and baked["last"] and baked["last"][0] == "INFO"
      and "channel" not in baked["last"][1], baked["last"])

# 4. The image being baked in the free Image Editor while it fills in, not in the pinned one; the
#    summary names the channel-packing target and what occluded the bake.
during = [json.load(open(p)) for p in sorted(glob.glob(os.path.join(OUT, "during_*.json")))]
shown = [d for d in during if d["running"] and d["free_editor"] == "Crate_AO"]
filling = pixels("filling") if os.path.exists(os.path.join(OUT, "filling.png")) else None
fx, fy, fw, fh = load("channel_baked")["free_rect"]
px, py, pw, ph = load("channel_baked")["pinned_rect"]
centre = lambda image, x, y, w, h: image[y + h // 4:y + 3 * h // 4, x + w // 4:x + 3 * w // 4].astype(int)
if filling is not None:
    free_px, pinned_px = centre(filling, fx, fy, fw, fh), centre(filling, px, py, pw, ph)
    differs = float(np.abs(free_px.mean(axis=(0, 1)) - pinned_px.mean(axis=(0, 1))).max())
else:
    differs = 0.0
channel = load("channel_baked")
check("image shown while it fills in", shown and all(d["pinned_editor"] == "Crate_ORM" for d in during)
      and differs > 30 and channel["free_editor"] == "Crate_AO",
      {"during, free editor": sorted({d["free_editor"] for d in during}), "pinned": channel["pinned_editor"],
       "free vs pinned editor's mean colour, largest channel difference": differs})
check("summary: channel target and occluders", channel["last"] and "the red channel of 'Crate_ORM'" in channel["last"][1]
      and "occluded by itself and 4 other objects" in channel["last"][1], channel["last"])
painting = load("painting_baked")
check("a painting Image Editor keeps its image", painting["seen_running"] and painting["free_mode"] == "PAINT"
      and painting["free_editor"] == "Crate_ORM", {k: painting[k] for k in ("free_editor", "free_mode", "last")})

# 5. The estimate prices the settings: Denoise and a second quantity change it.
plain, denoise, two = (load(n)["estimate"] for n in ("estimate_plain", "estimate_denoise", "estimate_two"))
check("estimate prices Denoise and a second quantity", plain and denoise != plain and two != plain,
      {"plain": plain, "denoise": denoise, "AO and thickness": two})

# 6. Only Local and the ground: the Occlusion line says the ground counts, the summary where it was.
line, local = load("only_local_ground")["occluded_by"], load("only_local_baked")
check("Only Local says the ground counts", "each object alone, and the ground" in line and local["last"]
      and "occluded by itself alone and the ground at" in local["last"][1], {"line": line, "summary": local["last"]})

# 7. The Image field's token.
check("image-name token", load("start")["placeholder"] == "{object}_AO", load("start")["placeholder"])

# Pictures for docs/: the sidebar over three states side by side; the greyed button; the editors.
crop = lambda image: image[stop:stop + min(sh, 640), sx:sx + sw]
save(np.concatenate([crop(pixels(n)) for n in (stills[0], "greyed", stills[-2])], axis=1), "docs_panel_still")
if filling is not None:
    save(filling[40:stop + min(sh, 640), sx:], "docs_panel_image_editor")
if os.path.exists(os.path.join(OUT, "occlusion.png")):
    save(crop(pixels("occlusion")), "docs_panel_only_local")
    # the same shot's lower rows: the Image section, Fix Seams under Margin
    save(pixels("occlusion")[stop + sh - 363:stop + sh, sx:sx + sw], "docs_panel_fix_seams")

with open(os.path.join(OUT, "verdict.json"), "w") as fh:
    json.dump(results, fh, indent=1)
failed = [item for item, r in results.items() if not r["ok"]]
print(f"{len(results) - len(failed)} of {len(results)} panel items pass" + (f"; failed: {failed}" if failed else ""))
sys.exit(1 if failed else 0)
