"""Which Embree the installed extension's scenes use, in a real Blender (not run by CI).

From the repository root, after ``python scripts/build_extension.py --platform linux-x64``:

    ../shared/tools/blender-gui.sh exec 'MC_AO_ZIP=$(ls dist/mc_ao-*-linux_x64.zip | head -1) \\
        blender -b --factory-startup --python tests/gui/check_embree.py'

It installs the zip into a temporary user repository, then prints whether core.tracing.embree_upload's C-API
upload is on, the library it calls, every Embree mapped into Blender, and a small bake's mean AO
against the exact value, and the Embree scene flags of the occlusion and contact scenes (robust mode
off and on, core.tracing.tracer.OCCLUSION_ROBUST). Seen in Debian's Blender 4.3 (2026-12-02): Blender links the system
libembree4 and its symbols are global, so embreex's extension calls it too, although its own copy
(embreex.libs) is mapped as well; the upload finds the system library from the scene's vtable and
uses the same one. With the bpy module it is embreex's own copy (tests/test_embree_upload.py).
Exits 1 when the upload is off or the bake is off the exact value.
"""

import importlib
import os
import sys
import tempfile

import bpy
import numpy as np

repos = bpy.context.preferences.extensions.repos
directory = tempfile.mkdtemp(prefix="mc_ao_embree_repo_")
repos.new(name="MC AO Embree check", module="mc_ao_embree_check", custom_directory=directory, source="USER")
print("install:", bpy.ops.extensions.package_install_files(filepath=os.environ["MC_AO_ZIP"],
                                                          repo="mc_ao_embree_check", enable_on_install=True))
package = next(m for m in sys.modules if m.startswith("bl_ext.mc_ao_embree_check.") and m.count(".") == 2)
upload = importlib.import_module(package + ".core.tracing.embree_upload")
core = importlib.import_module(package + ".core")
analytic = importlib.import_module(package + ".core.montecarlo.analytic")

on = upload.available()
print("C-API upload:", on, upload.reason() or "", "library:", upload._library_path())
print("Embree libraries mapped:", sorted({p for _, _, p in (upload._mapped_files() or []) if "embree" in p}))

# A unit plane under a square lid at height 0.3: AO per texel is 1 - the lid's form factor.
P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
F = np.array([[0, 1, 2], [0, 2, 3]])
plane = core.Mesh(P, F, uvs=P[F][:, :, :2], name="plane")
lid_corners = P * [0.5, 0.5, 1] + [0.25, 0.25, 0.3]
lid = core.Mesh(lid_corners, F, name="lid")
r = core.bake_ao(plane, [lid], resolution=8, samples=4096, threads=2, seed=1)
exact = analytic.texel_mean(lambda p: 1.0 - analytic.polygon_form_factor(p, lid_corners), 8, 8)
err = float(np.abs(r.ao - exact).max())
z = float(np.max(np.abs(r.ao - exact) / np.maximum(r.stderr, 1e-9)))
print(f"bake: largest |AO - exact| {err:.4f}, largest |z| {z:.2f}")
# The occlusion scene without Embree's robust mode, the contact scene with it (core.tracing.tracer).
tracing = importlib.import_module(package + ".core.tracing.tracer")
tracer = tracing.Tracer([plane, lid])
flags = (upload.scene_flags(tracer.scene), upload.scene_flags(tracer.contact_scene))
print("scene flags (occlusion, contact):", flags)
sys.exit(0 if on and z < 5 and flags == (0, upload.RTC_SCENE_FLAG_ROBUST) else 1)
