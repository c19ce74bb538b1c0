#!/usr/bin/env python3
"""agreement_table.py REF_DIR NAME [INTEGRATOR ...]: for the renders xml_agreement.sh left in
REF_DIR/ours, one row per integrator: agree.py's excess ratio over the whole image and without
the pixels brighter than 20 in the reference (emitters seen directly, where a light a pixel
wide makes camera hits rare and the halves' difference a poor noise estimate), the image mean
over the reference's, the 5th and 95th percentiles of the 16-px block means over the
reference's, and the block bias agree.py would flag at z 5 on the median block (5 times the
block's standard error, from both sides' halves, over the block's mean)."""
import os, sys
import numpy as np
from exr_images import read

refs, name = sys.argv[1], sys.argv[2]
ints = sys.argv[3:] or "pt bdpt vcm bpm pm ppm sppm pssmlt mmlt mlt".split()
ra, rb = read(f"{refs}/{name}.a.exr"), read(f"{refs}/{name}.b.exr")
r = 0.5 * (ra + rb)
bright = (r > 20).any(-1)
h, w = r.shape[0] // 16 * 16, r.shape[1] // 16 * 16
blocks = lambda img: img[:h, :w].reshape(h // 16, 16, w // 16, 16, 3).mean((1, 3))
print("| integrator | excess ratio | without emitters seen | mean / ref | block ratio p5-p95 | flags a block bias of |")
print("|---|---|---|---|---|---|")
for i in ints:
    paths = [f"{refs}/ours/{name}.{i}.{s}.exr" for s in (1, 2)]
    if not all(os.path.exists(p) for p in paths):
        print(f"| {i} | not rendered | | | | |")
        continue
    a, b = (read(p) for p in paths)
    d = 0.5 * (a + b) - r
    var = ((a - b) ** 2 + (ra - rb) ** 2) / 4
    ex = np.sum(d ** 2) / np.sum(var)
    ex_dim = np.sum(d[~bright] ** 2) / np.sum(var[~bright])
    ratio = blocks(0.5 * (a + b)) / blocks(r)
    se = np.sqrt(blocks(var) / 256)
    detect = np.median(5 * se / blocks(r))
    p5, p95 = np.percentile(ratio, [5, 95])
    print(f"| {i} | {ex:.3f} | {ex_dim:.3f} | {(a + b).mean() / (2 * r.mean()):.4f} | {p5:.3f}-{p95:.3f} | {100 * detect:.1f}% |")
