#!/usr/bin/env python3
"""island_excess.py A B [REF_A REF_B]: glass_tube's light reflection (rows 22-23, columns 31-32) and
agree.py's excess ratio split into that island and the rest: per image the island's summed
luminance and the image mean over the reference's; then the excess ratio over all pixels and
without the island, and the sums of (x - r)^2 and of the noise estimate on each part."""
import sys, numpy as np
from exr_images import read
Y = np.array([0.2126, 0.7152, 0.0722])
R = 'tests/scenes/references/glass_tube'
a, b = read(sys.argv[1]), read(sys.argv[2])
ra, rb = (read(p) for p in sys.argv[3:5]) if len(sys.argv) > 4 else (read(R + '.a.exr'), read(R + '.b.exr'))
r = 0.5 * (ra + rb)
d = 0.5 * (a + b) - r
var = ((a - b) ** 2 + (ra - rb) ** 2) / 4
m = np.ones(d.shape[:2], bool)
m[22:24, 31:33] = False
for name, img in ((sys.argv[1], a), (sys.argv[2], b)):
    print(f"{name}: island {np.sum(img[~m] @ Y):.2f} (reference {np.sum(r[~m] @ Y):.2f}), "
          f"image mean {(img @ Y).mean() / (r @ Y).mean():.4f} of the reference's")
print(f"excess ratio {np.sum(d**2) / np.sum(var):.3f}, without the island {np.sum(d[m]**2) / np.sum(var[m]):.3f}; "
      f"sum (x-r)^2: rest {np.sum(d[m]**2):.2f}, island {np.sum(d[~m]**2):.2f}; "
      f"sum noise: rest {np.sum(var[m]):.2f}, island {np.sum(var[~m]):.2f}")
