"""strat.py DIR... : per depth k = s + t - 2 and strategy, the block (24..40)^2 mean luminance and the
image-mean luminance, averaged over the DIRs (several seeds); also per-depth sums."""
import sys, os, re, numpy as np, OpenEXR
from collections import defaultdict
from exr_images import read
Y = np.array([0.2126, 0.7152, 0.0722])
dirs = sys.argv[1:]
acc = defaultdict(lambda: np.zeros((len(dirs), 2)))
for i, d in enumerate(dirs):
    for f in os.listdir(d):
        m = re.match(r's(\d+)_t(\d+)\.exr', f)
        if not m: continue
        s, t = int(m[1]), int(m[2])
        img = read(os.path.join(d, f)) @ Y
        acc[(s + t - 2, s)][i] = [img[24:40, 24:40].mean(), img.mean()]
depth = defaultdict(lambda: np.zeros((len(dirs), 2)))
for (k, s), v in acc.items(): depth[k] += v
tot = sum(depth.values())
print(f"total: block {tot[:,0].mean():.5f} image {tot[:,1].mean():.5f}")
for k in sorted(depth):
    v = depth[k]; 
    if k > 12: continue
    parts = ' '.join(f"s{s}:{acc[(k,s)][:,0].mean():.5f}" for s in range(k + 2) if (k, s) in acc and acc[(k,s)][:,0].mean() > 1e-5)
    print(f"depth {k:2d}: block {v[:,0].mean():.5f} (se {v[:,0].std(ddof=1)/np.sqrt(len(dirs)) if len(dirs)>1 else 0:.5f})  image {v[:,1].mean():.5f} | {parts}")
