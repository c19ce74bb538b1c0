# %% [markdown]
# The study's error-against-time figure for one scene, from Python (docs/python.md).
# Run from the repository root: python docs/examples/error_vs_time.py [SCENE] [SECONDS,...] [REF_SPP]
import sys

import stagelight

scene = stagelight.load(sys.argv[1] if len(sys.argv) > 1 else "scenes/cornell_box.ron")
budgets = [float(b) for b in (sys.argv[2] if len(sys.argv) > 2 else "1,2,4,8").split(",")]
ref_spp = int(sys.argv[3]) if len(sys.argv) > 3 else 1024

# %% A reference: checkpointed, so running this again resumes or reuses it.
ref = stagelight.reference(scene, spp=ref_spp, checkpoint="reference/example.exr").image

# %% The study's integrators at each budget, measured against it (rows as dicts or a DataFrame).
rows = stagelight.compare(scene, ["pt", "bdpt", "pm", "ppm", "mlt"], budgets, ref)
rows = rows if isinstance(rows, list) else rows.to_dict("records")
for r in rows:
    print(f"{r['integrator']:>5} {r['budget']:>6} s  relMSE {r['relmse']:.4g}")

# %% The figure: relMSE against wall seconds, log-log.
try:
    import matplotlib.pyplot as plt
except ImportError:
    plt = None
    print("(no matplotlib: the table above is the figure's data)")
for name in dict.fromkeys(r["integrator"] for r in rows) if plt else []:
    runs = [r for r in rows if r["integrator"] == name]
    plt.loglog([r["wall"] for r in runs], [r["relmse"] for r in runs], "o-", label=name)
if plt:
    plt.xlabel("seconds"), plt.ylabel("relMSE"), plt.legend(), plt.savefig("error_vs_time.png")
