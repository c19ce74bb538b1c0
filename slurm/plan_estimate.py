#!/usr/bin/env python3
"""On paper: how long the tasks of a sharded comparison's plan take, from measured rates.

    slurm/plan_estimate.py PLAN.ron RATES.csv

PLAN.ron is the plan `stagelight slurm --shards N -- compare ...` writes. RATES.csv has the
columns scene,render,setup_s,pass_s,whole_s: for a render split into shards (`render` the
integrator, `pt` or `bdpt`, or the plan's render name, e.g. `reference`) a shard's own setup
and the seconds of one pass, measured on one node; for a whole run (`render` the plan's name
of it, e.g. `mlt-841spp`) its seconds. A shard of p passes is taken to cost setup_s + p x
pass_s (the task's scene load and warm-up pass are counted in every shard's setup: an
overestimate). Prints the slowest task's seconds (the wall time of the array, one node per
task), and the sum of all tasks' (one node doing it all)."""
import csv
import os
import re
import sys

plan_text = open(sys.argv[1]).read()
rates = {}
for row in csv.DictReader(open(sys.argv[2])):
    rates[(row["scene"], row["render"])] = row

tasks = int(re.search(r"\btasks:\s*(\d+)", plan_text).group(1))
load = [0.0] * (tasks + 1)
missing = set()
scene = None
# Scenes and renders appear in order: `key: "..."` opens a scene, each render has its name,
# integrator, passes, whole and tasks in that order.
token = re.compile(
    r'key:\s*"([^"]*)"|name:\s*"([^"]*)",\s*integrator:\s*"([^"]*)",\s*passes:\s*(\d+),'
    r"\s*whole:\s*(true|false),\s*tasks:\s*\[([^\]]*)\]"
)
for m in token.finditer(plan_text):
    if m.group(1) is not None:
        scene = m.group(1)
        continue
    name, integrator, passes, whole = m.group(2), m.group(3), int(m.group(4)), m.group(5)
    shard_tasks = [int(t) for t in m.group(6).split(",") if t.strip()]
    if whole == "true":
        rate = rates.get((scene, name))
        if rate is None:
            missing.add(f"{scene},{name} (a whole run)")
            continue
        load[shard_tasks[0]] += float(rate["whole_s"])
        continue
    rate = rates.get((scene, name)) or rates.get((scene, integrator))
    if rate is None:
        missing.add(f"{scene},{integrator} (shards)")
        continue
    setup, per_pass = float(rate["setup_s"]), float(rate["pass_s"])
    count = len(shard_tasks)
    for j, task in enumerate(shard_tasks):
        # PassRange::shard: shard j of count covers passes total*j/count .. total*(j+1)/count.
        first, end = passes * j // count, passes * (j + 1) // count
        load[task] += setup + per_pass * (end - first)
if missing:
    sys.exit("no rate for: " + "; ".join(sorted(missing)))
busiest = max(range(1, tasks + 1), key=lambda t: load[t])
total = sum(load)
if os.environ.get("EVERY_TASK"):
    for t in range(1, tasks + 1):
        print(f"task {t}: {load[t]:.1f} s")
print(f"{tasks} tasks: slowest task {busiest}, {load[busiest]:.1f} s; all tasks {total:.1f} s "
      f"({total / 60:.1f} min on one node)")
