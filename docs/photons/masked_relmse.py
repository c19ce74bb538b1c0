"""relMSE over the pixels of a mask (issue 16, item 5: the mirror's pixels of mirror_box).

    python masked_relmse.py REFERENCE.exr MASK.exr IMAGE.exr...

A pixel counts when every channel of MASK is above 0.99 (the mask is a render of the scene
with every surface black but the one measured, which emits 1: pixels wholly on it). The
relMSE is stagelight's: the mean over pixels and channels of (x - r)^2 / (r^2 + 0.01).
Reads EXRs with Mitsuba 3's Bitmap (/tmp/mi-venv/bin/python).
"""

import sys

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")


def read(path):
    return np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]


def relmse(x, r):
    return float(np.mean((x - r) ** 2 / (r * r + 0.01)))


reference, mask = read(sys.argv[1]), read(sys.argv[2])
on = np.all(mask > 0.99, axis=-1)
print(f"# {on.sum()} pixels on the mask of {on.size}")
print("image\trelmse_mask\trelmse_all")
for path in sys.argv[3:]:
    x = read(path)
    print(f"{path}\t{relmse(x[on], reference[on]):.4g}\t{relmse(x, reference):.4g}")
