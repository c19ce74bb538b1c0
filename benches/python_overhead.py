"""stagelight.render against the command line: samples/s on the same scene, alternated.

    cargo build --release && pip install ./python
    python benches/python_overhead.py [SCENE] [SPP] [ROUNDS] [THREADS]

Each round runs `stagelight render` (its report's samples/s: samples over the render's wall
time, scene loading excluded) and stagelight.render on a scene loaded once (the same measure,
and samples over the whole Python call, conversion to NumPy included), in alternating order.
"""

import re
import subprocess
import sys
import time
from pathlib import Path

import stagelight

ROOT = Path(__file__).resolve().parents[1]
scene_path = sys.argv[1] if len(sys.argv) > 1 else str(ROOT / "scenes" / "cornell_box.ron")
spp = int(sys.argv[2]) if len(sys.argv) > 2 else 64
rounds = int(sys.argv[3]) if len(sys.argv) > 3 else 3
threads = sys.argv[4] if len(sys.argv) > 4 else "2"
binary = ROOT / "target" / "release" / "stagelight"


def mega(text: str) -> float:
    value, unit = re.search(r"samples/s\s+([0-9.]+)\s*(\w?)", text).groups()
    return float(value) * {"k": 1e3, "M": 1e6, "G": 1e9}.get(unit, 1.0)


scene = stagelight.load(scene_path)
stagelight.render(scene, spp=1, threads=int(threads))  # warm-up
print(f"{scene_path}, {spp} spp, {threads} threads; samples/s")
print("round  cli_engine  python_engine  python_call")
for i in range(rounds):
    # The order alternates too, so neither side always runs on a machine the other warmed.
    first_python = i % 2 == 1
    if first_python:
        start = time.perf_counter()
        r = stagelight.render(scene, spp=spp, threads=int(threads))
        call = r.samples / (time.perf_counter() - start)
    out = subprocess.run(
        [str(binary), "render", scene_path, "--spp", str(spp), "--threads", threads,
         "--quiet", "-o", "/tmp/stagelight_overhead.exr"],
        capture_output=True, text=True, check=True,
    ).stdout
    cli = mega(out)
    if not first_python:
        start = time.perf_counter()
        r = stagelight.render(scene, spp=spp, threads=int(threads))
        call = r.samples / (time.perf_counter() - start)
    print(f"{i + 1:>5}  {cli / 1e6:>10.3f}M  {r.stats.samples_per_second / 1e6:>12.3f}M  {call / 1e6:>10.3f}M")
