#!/usr/bin/env python3
"""render_xml.py (../shared/mitsuba/) with a time budget: renders a Mitsuba scene XML in two
independent halves, chunk after chunk, and rewrites OUT/NAME.{a,b,}.exr and NAME.json after
every round, so a long reference can be stopped at any time and used as it stands.
Usage: render_xml_budget.py SCENE.xml OUT NAME CHUNK BUDGET_SECONDS [VARIANT]"""
import json, os, sys, time
import numpy as np, mitsuba as mi
xml, out, name, chunk, budget = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), float(sys.argv[5])
mi.set_variant(sys.argv[6] if len(sys.argv) > 6 else 'llvm_ad_rgb')
scene = mi.load_file(xml, spp=chunk)
acc = {'a': 0.0, 'b': 0.0}; n = 0; k = 0; t0 = time.perf_counter()
os.makedirs(out, exist_ok=True)
def write(p, img):
    mi.Bitmap(np.ascontiguousarray(img, dtype=np.float32)).write(p + '.partial.exr'); os.replace(p + '.partial.exr', p)
while time.perf_counter() - t0 < budget:
    for h, off in (('a', 0), ('b', 1)):
        acc[h] = acc[h] + np.array(mi.render(scene, spp=chunk, seed=(2 * k + off) * 100003), dtype=np.float64)[..., :3] * chunk
    n += chunk; k += 1
    a, b = acc['a'] / n, acc['b'] / n
    for suffix, img in (('.a', a), ('.b', b), ('', 0.5 * (a + b))):
        write(os.path.join(out, name + suffix + '.exr'), img)
    st = {'xml': os.path.basename(xml), 'spp_per_half': n, 'seconds': round(time.perf_counter() - t0, 1),
          'mean_rgb': [float(x) for x in (0.5 * (a + b)).mean((0, 1))],
          'relMSE_a_vs_b': float(np.mean((a - b) ** 2 / (b ** 2 + 0.01)))}
    json.dump(st, open(os.path.join(out, name + '.json'), 'w'), indent=1)
print(json.dumps(st))
