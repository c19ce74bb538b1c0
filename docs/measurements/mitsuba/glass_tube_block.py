"""block.py REF.exr IMG... : per image, the 16x16 block at (24,24) mean RGB over the reference's;
then the mean over images with its standard error, and how many are >5% dark (luminance)."""
import sys, numpy as np, OpenEXR
from exr_images import read
Y = np.array([0.2126, 0.7152, 0.0722])
ref = read(sys.argv[1])[24:40, 24:40].mean((0, 1))
rs = []
for p in sys.argv[2:]:
    b = read(p)[24:40, 24:40].mean((0, 1))
    rs.append(b / ref); 
rs = np.array(rs)
lum = rs @ (Y * ref) / (Y @ ref)
for p, r, l in zip(sys.argv[2:], rs, lum): print(f"{p}: {r[0]:.3f} {r[1]:.3f} {r[2]:.3f}  lum {l:.3f}")
n = len(rs)
if n > 1:
    m, se = rs.mean(0), rs.std(0, ddof=1) / np.sqrt(n)
    print(f"n={n} mean {m.round(3)} se {se.round(3)}; lum mean {lum.mean():.3f} se {lum.std(ddof=1)/np.sqrt(n):.3f}; "
          f">5% dark (lum): {(lum < 0.95).sum()} of {n}; median lum {np.median(lum):.3f}")
