#!/usr/bin/env python3
"""excess_mask.py A B REF_A REF_B: agree.py's excess ratio, over the whole image and without the four pixels of
the light's reflection in glass_tube's sphere (rows 22-23, columns 31-32)."""
import sys, numpy as np
from exr_images import read
a,b,ra,rb=(read(p) for p in sys.argv[1:5])
d=0.5*(a+b)-0.5*(ra+rb); var=((a-b)**2+(ra-rb)**2)/4
m=np.ones(d.shape[:2],bool); m[22:24,31:33]=False
print(f"excess ratio all {np.sum(d**2)/np.sum(var):.3f}; without the light's 4-pixel reflection (rows 22-23, cols 31-32) {np.sum(d[m]**2)/np.sum(var[m]):.3f}")
