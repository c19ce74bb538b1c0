# strategy_variance.py DIR1 DIR2 REF.exr: where BDPT's variance comes from. DIR1, DIR2: two renders
# (different seeds) made with --strategy-images DIR (and -o DIR.exr); prints each kind of strategy's
# share of the summed per-strategy variance (relMSE units) and the whole image's variance.
import sys, os, re, numpy as np, OpenEXR
def load(p):
    f = OpenEXR.File(p); ch = f.parts[0].channels
    a = ch["RGB"].pixels if "RGB" in ch else np.stack([ch[c].pixels for c in "RGB"], -1)
    return np.asarray(a, dtype=np.float64)
ref = load(sys.argv[3]); den = ref**2 + 0.01
d1, d2 = sys.argv[1], sys.argv[2]
tot = ((load(d1 + ".exr") - load(d2 + ".exr"))**2 / 2 / den).mean()
rows = []
for f in os.listdir(d1):
    m = re.match(r"s(\d+)_t(\d+).exr", f)
    if not m or not os.path.exists(os.path.join(d2, f)): continue
    s, t = int(m.group(1)), int(m.group(2))
    a, b = load(os.path.join(d1, f)), load(os.path.join(d2, f))
    v = ((a - b)**2 / 2 / den).mean()
    mean = (a + b).mean() / 2
    rows.append((v, s, t, mean))
S = sum(r[0] for r in rows)
print(f"variance of the whole image (relMSE units, per image of these spp): {tot:.4f}; sum over strategies {S:.4f}")
kind = {}
for v, s, t, m in rows:
    k = "s=0 (camera path hits light)" if s == 0 else "s=1 (light sample, NEE)" if s == 1 and t >= 2 else "t=1 (light tracing)" if t == 1 else "s>=2, t>=2 (connections)"
    kind.setdefault(k, [0, 0]); kind[k][0] += v; kind[k][1] += m
for k, (v, m) in sorted(kind.items(), key=lambda x: -x[1][0]):
    print(f"  {k:32} {100*v/S:5.1f}% of the variance, {100*m/sum(r[3] for r in rows):5.1f}% of the image")
depth = {}
for v, s, t, m in rows:
    d = s + t - 2; depth.setdefault(d, [0, 0]); depth[d][0] += v; depth[d][1] += m
print("  by path depth (bounces): variance share / image share")
print("   " + "  ".join(f"{d}:{100*v/S:.0f}/{100*m/sum(r[3] for r in rows):.0f}" for d, (v, m) in sorted(depth.items()) if d < 12))
rows.sort(reverse=True)
print("  top strategies (s,t): variance share, image share")
for v, s, t, m in rows[:12]:
    print(f"    ({s},{t}) {100*v/S:5.1f}%  {100*m/sum(r[3] for r in rows):5.1f}%")
