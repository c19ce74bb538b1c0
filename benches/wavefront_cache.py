#!/usr/bin/env python3
"""Simulated cache behaviour of PT per system, for each wavefront size and the megakernel.

    python3 benches/wavefront_cache.py [--scene scenes/cornell_box.ron] [--size 128] [--spp 64]
        [--wavefronts 1024,4096,16384,65536,262144,1048576] [--ll 33554432,16,64]
        [--bin target/release/stagelight] [--out DIR]

Runs `stagelight render` on one thread under `valgrind --tool=callgrind --cache-sim=yes` (this
machine exposes no hardware counters: `perf stat -e instructions true` says "not supported"),
once per wavefront size and once with `--kernel megakernel`, every run rendering the same
samples (--size x --size pixels, --spp passes: 2^20 samples by default, so even the largest
wave is full). On one thread every system's work runs inside its `System::run` call, so the
inclusive cost of that function (callgrind_annotate --inclusive=yes) is the system's. Prints a
Markdown table: per configuration and system, its share of the instructions, data references
per sample, and its D1 and last-level miss rates (misses / data references, reads and writes,
as cg_annotate's "D1 miss rate" and "LLd miss rate").

The simulated caches are this machine's (AMD EPYC, Zen 5, as lscpu and CPUID report them):
I1 32 KiB 8-way, D1 48 KiB 12-way, LL = the L3, 32 MiB 16-way, 64-byte lines. Valgrind simulates
two levels only, so the 1 MiB L2 is not modelled; `--ll 1048576,16,64` simulates it as the last
level instead.
"""

import argparse
import os
import re
import subprocess
import sys
import tempfile

EVENTS = ["Ir", "Dr", "Dw", "D1mr", "D1mw", "DLmr", "DLmw"]


def shrunk_scene(scene, size, to):
    text = open(scene).read()
    text = text.replace("camera: (", f"camera: (\n        width: {size},\n        height: {size},", 1)
    with open(to, "w") as f:
        f.write(text)


def run(args, label, extra, work):
    out = os.path.join(work, f"callgrind.{label}.out")
    exr = os.path.join(work, f"{label}.exr")
    cmd = [
        "valgrind", "--tool=callgrind", "--cache-sim=yes",
        "--I1=32768,8,64", "--D1=49152,12,64", f"--LL={args.ll}",
        f"--callgrind-out-file={out}",
        args.bin, "render", os.path.join(work, "scene.ron"), "--spp", str(args.spp),
        "--threads", "1", "--quiet", "-o", exr,
    ] + extra
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return out


def inclusive_costs(out):
    """Each function's inclusive costs, by name."""
    text = subprocess.run(
        ["callgrind_annotate", "--inclusive=yes", "--threshold=100",
         "--show=" + ",".join(EVENTS), out],
        check=True, capture_output=True, text=True,
    ).stdout
    costs = {}
    # A zero count prints as "."; a count may carry its share, "(12.3%)".
    number = r"([\d,]+|\.)(?: \([^)]*\))?"
    line_re = re.compile(r"^\s*" + r"\s+".join([number] * len(EVENTS)) + r"\s+(.*)$")
    for line in text.splitlines():
        m = line_re.match(line)
        if not m:
            continue
        values = [0 if v == "." else int(v.replace(",", "")) for v in m.groups()[: len(EVENTS)]]
        name = m.groups()[len(EVENTS)]
        if name.startswith("=>"):
            continue  # a call line of the annotated source, not a function's total
        # Lines come by inclusive cost, largest first: a function's first line is its whole
        # cost (later ones are inlined pieces attributed to other files).
        costs.setdefault(name.split(":", 1)[-1] if name.startswith("/") else name, values)
    return costs


# System::run of each system: "<stagelight::systems::trace::closest::TraceClosest as ...>::run"
SYSTEM_RE = re.compile(r"<stagelight::systems::\w+::\w+::(\w+) as stagelight::pipeline::System<([\w:]+)>>::run")


def per_system(costs):
    systems = {}
    for name, values in costs.items():
        m = SYSTEM_RE.search(name)
        if m:
            snake = re.sub(r"(?<!^)([A-Z])", r"_\1", m.group(1)).lower()
            if values[0] > systems.get(snake, [0])[0]:
                systems[snake] = values
    return systems


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default="scenes/cornell_box.ron")
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--wavefronts", default="1024,4096,16384,65536,262144,1048576")
    p.add_argument("--ll", default="33554432,16,64")
    p.add_argument("--bin", default="target/release/stagelight")
    p.add_argument("--out", default=None, help="keep the callgrind files here")
    args = p.parse_args()
    work = args.out or tempfile.mkdtemp(prefix="wavefront_cache_")
    os.makedirs(work, exist_ok=True)
    shrunk_scene(args.scene, args.size, os.path.join(work, "scene.ron"))
    samples = args.size * args.size * args.spp
    configs = [(f"wavefront {n}", ["--wavefront", n]) for n in args.wavefronts.split(",")]
    configs.append(("megakernel", ["--kernel", "megakernel"]))
    print(f"{args.scene} at {args.size}x{args.size}, {args.spp} spp ({samples} samples), 1 thread;"
          f" D1 48 KiB 12-way, LL {args.ll} (size,ways,line)")
    print("| kernel | system | instructions per sample | share | data refs per sample | D1 miss rate | LL miss rate | D1 misses per sample | LL misses per sample |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, extra in configs:
        out = run(args, label.replace(" ", "_"), extra, work)
        costs = per_system(inclusive_costs(out))
        total = [sum(v[i] for v in costs.values()) for i in range(len(EVENTS))]
        rows = sorted(costs.items(), key=lambda kv: -kv[1][0]) + [("all systems", total)]
        for name, (ir, dr, dw, d1mr, d1mw, dlmr, dlmw) in rows:
            refs = dr + dw
            d1, ll = d1mr + d1mw, dlmr + dlmw
            print(f"| {label} | {name} | {ir / samples:.0f} | {100 * ir / max(total[0], 1):.1f}% |"
                  f" {refs / samples:.0f} | {100 * d1 / max(refs, 1):.2f}% | {100 * ll / max(refs, 1):.3f}% |"
                  f" {d1 / samples:.2f} | {ll / samples:.3f} |")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
