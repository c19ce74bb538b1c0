#!/usr/bin/env python3
"""Embree 4 against stagelight on the same rays (issue 30).

Traces the rays a `stagelight rays SCENE --out DIR` folder holds with Embree (the `embreex`
binding of Embree 4.4: rtcIntersect1 / rtcOccluded1, one ray at a time, on one thread) and
with `stagelight bench --rays DIR --threads 1` in the same run, bounce group by bounce group,
and prints both rays/s (medians of --runs timed runs after a warm-up), their ratio, and how
many hits differ. Both are timed --rounds times, one after the other (stagelight in a fresh
process each round); the ratio printed is the median of the rounds' ratios, with their
range, since the machine's state (caches, huge pages) drifts between runs.

A closest hit differs when one tracer hits and the other does not, or when both hit and the
distances differ by more than a relative 1e-4 (a different primitive at the same distance, as
on a shared edge or two coincident triangles, is counted apart and not as a difference). A
shadow ray differs when one tracer finds it occluded and the other does not. Of the
differences, those where Embree's hit is at t = 0 are counted apart ("Embree t=0"). embreex
traces every ray from t = 0 (it sets tnear = 0), so a ray leaving a surface from a point on
it can hit that surface at t = 0, which stagelight's triangle test rejects (it takes only hits
beyond the error bound of t, and spawns rays so that no real hit is that close). Such a ray
stops at once in Embree: a fifth to two fifths of the bounced rays did, which made Embree look
up to 1.7x faster (big_1m's first shadow rays, 2026-11-28). So Embree's rays start a hundred-thousandth of the scene's diagonal
further along (t_max shortened as much, the distances it finds lengthened back), which no
hit at t = 0 survives; a real hit that close is lost, and counted in "differ".

stagelight does not depend on this script. Run it with a Python that has embreex and numpy:

    python -m venv venv && venv/bin/pip install embreex numpy
    stagelight rays scenes/cornell_box.ron --out rays/cornell_box --spp 16
    venv/bin/python benches/embree_rays.py rays/cornell_box --runs 5

Embree's scene is built with RTC_SCENE_FLAG_ROBUST (embreex's default; its watertight mode,
as stagelight's traversal always is); --fast builds it without. Embree's timing includes
embreex's per-ray loop (copying each ray into an RTCRayHit and the hit out, in Cython without
the GIL). So each group is also timed on as many rays that miss the scene's bounds (from a
point beyond them, pointing away): Embree returns from those at its root, and what they
take is the binding's cost per ray plus one box test. The second pair of columns takes that
off Embree's time ("Embree - binding"), which slightly flatters Embree (the root test is
part of tracing).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

MISS = 0xFFFFFFFF

# How far along each ray Embree starts, in units of the scene's diagonal (see the top).
SKIP = 1e-5


def read_mesh(path):
    """Triangles of a binary little-endian PLY as `stagelight rays` writes it (float x, y, z
    vertices; faces as a uchar count of 3 and uint indices): an array (faces, 3, 3)."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        sys.exit(f"{path}: not a PLY file")
    header = data[:end].decode("ascii").splitlines()
    body = data[end + len(b"end_header\n"):]
    if "format binary_little_endian 1.0" not in header:
        sys.exit(f"{path}: expected binary_little_endian PLY")
    vertices = faces = None
    for line in header:
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            vertices = int(words[2])
        elif words[:2] == ["element", "face"]:
            faces = int(words[2])
    expected = [
        "property float x", "property float y", "property float z",
        "property list uchar uint vertex_indices",
    ]
    if vertices is None or faces is None or any(p not in header for p in expected):
        sys.exit(f"{path}: not the layout `stagelight rays` writes")
    v = np.frombuffer(body, dtype="<f4", count=3 * vertices).reshape(vertices, 3)
    face_dtype = np.dtype([("n", "u1"), ("i", "<u4", 3)])
    f = np.frombuffer(body, dtype=face_dtype, count=faces, offset=12 * vertices)
    if faces and not (f["n"] == 3).all():
        sys.exit(f"{path}: a face that is not a triangle")
    return v[f["i"]].astype(np.float32)


def groups(spans):
    """Row ranges of bounce 0, bounce 1 and bounces 2+, as `bench --rays` times them."""
    out = []
    for name, lo, hi in [("bounce 0", 0, 1), ("bounce 1", 1, 2), ("bounces 2+", 2, 1 << 62)]:
        s = [b for b in spans if lo <= b["bounce"] < hi]
        count = sum(b["count"] for b in s)
        if count:
            out.append((name, s[0]["first"], count))
    return out


def time_embree(scene, origins, dirs, t_max, query, runs):
    """Median seconds of `runs` timed runs (after one warm-up) and the last run's result."""
    seconds = []
    result = None
    for run in range(runs + 1):
        dists = t_max.copy()  # embreex writes the hit distances into this array
        start = time.perf_counter()
        result = scene.run(origins, dirs, dists=dists, query=query,
                           output=1 if query == "INTERSECT" else None)
        elapsed = time.perf_counter() - start
        if run > 0:
            seconds.append(elapsed)
    return float(np.median(seconds)), result


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dir", help="a folder written by `stagelight rays`")
    parser.add_argument("--runs", type=int, default=5, help="timed runs per group (median)")
    parser.add_argument("--rounds", type=int, default=3,
                        help="rounds of both tracers, one after the other (median ratio)")
    parser.add_argument("--stagelight", default=None,
                        help="the stagelight binary (default: target/release/stagelight)")
    parser.add_argument("--fast", action="store_true",
                        help="build Embree's scene without RTC_SCENE_FLAG_ROBUST")
    parser.add_argument("--json", default=None, help="also write the table as JSON here")
    args = parser.parse_args()

    try:
        from embreex import rtcore_scene, mesh_construction
    except ImportError:
        sys.exit("embreex is missing: pip install embreex numpy")

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    binary = args.stagelight or os.path.join(root, "target", "release", "stagelight")

    with open(os.path.join(args.dir, "rays.json")) as f:
        index = json.load(f)
    triangles = read_mesh(os.path.join(args.dir, "mesh.ply"))
    rays = {
        "closest": np.load(os.path.join(args.dir, "closest.npy")),
        "shadow": np.load(os.path.join(args.dir, "shadow.npy")),
    }
    n_closest = len(rays["closest"])

    scene = rtcore_scene.EmbreeScene(robust=not args.fast)
    mesh_construction.TriangleMesh(scene, triangles)
    start = time.perf_counter()
    probe = np.zeros((1, 3), np.float32)
    scene.run(probe, probe + np.float32(1), query="OCCLUDED")  # commits (builds) the scene
    build = time.perf_counter() - start

    groups_of = {kind: groups(index[kind]) for kind in ["closest", "shadow"]}
    low, high = triangles.reshape(-1, 3).min(0), triangles.reshape(-1, 3).max(0)
    extent = float(np.linalg.norm(high - low))
    skips = {}
    # Rays that miss at the root, as many as the largest group: from beyond the bounds' far
    # corner, pointing further away.
    most = max(count for spans in groups_of.values() for _, _, count in spans)
    away = np.ones(3, np.float32) / np.float32(np.sqrt(3.0))
    missing = (np.tile(high + (high - low) + 1, (most, 1)).astype(np.float32),
               np.tile(away, (most, 1)).astype(np.float32),
               np.full(most, np.float32(1e30)))
    inputs = {}
    for kind, spans in groups_of.items():
        for name, first, count in spans:
            rows = rays[kind][first:first + count]
            if not (rows[:, 3] == 0).all():
                sys.exit(f"{kind}.npy: a ray with t_min != 0 (embreex traces from t = 0)")
            origins, dirs = rows[:, 0:3], rows[:, 4:7]
            # The start moved along each ray past any hit at t = 0 (see above), in t's units.
            step = np.float32(SKIP * extent) / np.linalg.norm(dirs, axis=1).astype(np.float32)
            skips[(kind, name)] = step
            inputs[(kind, name)] = (np.ascontiguousarray(origins + dirs * step[:, None]),
                                    np.ascontiguousarray(dirs),
                                    np.ascontiguousarray(rows[:, 7] - step))

    # Rounds: stagelight (a fresh process) then Embree, each group timed by both per round.
    ours_rounds, embree_rounds, binding_rounds, results = [], [], [], {}
    for _ in range(args.rounds):
        with tempfile.TemporaryDirectory() as tmp:
            saved = os.path.join(tmp, "ours.json")
            command = [binary, "bench", "--rays", args.dir, "--threads", "1",
                       "--runs", str(args.runs), "--save", saved]
            done = subprocess.run(command, capture_output=True, text=True)
            if done.returncode != 0:
                sys.exit(f"{' '.join(command)} failed:\n{done.stderr}")
            with open(saved) as f:
                ours = json.load(f)
        ours_rounds.append({(g["kind"], g["group"]): g["median_seconds"]
                            for g in ours["groups"]})
        seconds, binding = {}, {}
        for key, (origins, dirs, t_max) in inputs.items():
            query = "INTERSECT" if key[0] == "closest" else "OCCLUDED"
            seconds[key], results[key] = time_embree(scene, origins, dirs, t_max, query,
                                                     args.runs)
            n = len(origins)
            binding[key], missed = time_embree(scene, *(a[:n] for a in missing), query,
                                               args.runs)
            if (missed["primID"] >= 0 if query == "INTERSECT" else missed == 0).any():
                sys.exit("a ray meant to miss the scene's bounds hit it")
        embree_rounds.append(seconds)
        binding_rounds.append(binding)
    hits = np.load(os.path.join(args.dir, "hits.npy"))

    print(f"{args.dir}: {len(triangles)} triangles; Embree built in {build:.3f} s "
          f"({'fast' if args.fast else 'robust'}), stagelight in {ours['build_seconds']:.3f} s")
    print(f"stagelight: {ours['machine']['cpu']}, 1 thread; medians of {args.runs} runs, "
          f"{args.rounds} rounds (ratio: the median of the rounds' ratios, and their range)")
    print(f"{'rays':<8} {'group':<11} {'count':>9} {'Embree Mr/s':>12} "
          f"{'ours Mr/s':>10} {'ours/Embree':>12} {'range':>11} "
          f"{'Embree - binding Mr/s':>22} {'ours/(Embree - binding)':>24} {'differ':>7} "
          f"{'Embree t=0':>11} {'same t, other prim':>19}")
    table = []
    for kind, spans in groups_of.items():
        total = {"count": 0, "differ": 0, "at_zero": 0, "other": 0}
        for name, first, count in spans:
            origins, dirs, t_max = inputs[(kind, name)]
            result = results[(kind, name)]
            offset = first if kind == "closest" else n_closest + first
            mine = hits[offset:offset + count]
            other_primitive = 0
            if kind == "closest":
                e_prim = result["primID"].astype(np.int64)
                e_hit = e_prim >= 0
                e_t = np.where(e_hit, result["tfar"] + skips[(kind, name)], np.inf)
                o_hit = mine["primitive"] != MISS
                both = e_hit & o_hit
                with np.errstate(invalid="ignore", divide="ignore"):
                    rel = np.abs(mine["t"] - e_t) / np.abs(e_t)
                t_differ = both & (rel > 1e-4)
                differing = (e_hit != o_hit) | t_differ
                at_zero = int((differing & (e_t == 0)).sum())
                other_primitive = int((both & ~t_differ & (e_prim != mine["primitive"])).sum())
            else:
                e_occluded = result == 0
                o_occluded = mine["primitive"] != MISS
                differing = e_occluded != o_occluded
                # Where Embree's occluder is: the differing rays traced again for their hit.
                k = np.nonzero(differing)[0]
                again = scene.run(origins[k], dirs[k], dists=t_max[k].copy(), output=1)
                at_zero = int(((again["primID"] >= 0) & (again["tfar"] == 0)).sum())
            differ = int(differing.sum())
            table.append(row_of(kind, name, count, [r[(kind, name)] for r in embree_rounds],
                                [r[(kind, name)] for r in binding_rounds],
                                [r[(kind, name)] for r in ours_rounds],
                                differ, at_zero, other_primitive))
            print_row(table[-1])
            for key, value in [("count", count), ("differ", differ), ("at_zero", at_zero),
                               ("other", other_primitive)]:
                total[key] += value
        if spans:
            names = [name for name, _, _ in spans]
            table.append(row_of(
                kind, "all", total["count"],
                [sum(r[(kind, n)] for n in names) for r in embree_rounds],
                [sum(r[(kind, n)] for n in names) for r in binding_rounds],
                [sum(r[(kind, n)] for n in names) for r in ours_rounds],
                total["differ"], total["at_zero"], total["other"]))
            print_row(table[-1])
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"dir": args.dir, "runs": args.runs, "rounds": args.rounds,
                       "robust": not args.fast, "cpu": ours["machine"]["cpu"],
                       "rows": table}, f, indent=2)


def row_of(kind, group, count, embree_seconds, binding_seconds, ours_seconds, differ, at_zero,
           other):
    """A table row from each round's seconds of both tracers and of the binding's rays that
    miss at the root."""
    ratios = [e / o for e, o in zip(embree_seconds, ours_seconds)]
    traced = [e - b for e, b in zip(embree_seconds, binding_seconds)]
    net_ratios = [t / o for t, o in zip(traced, ours_seconds)]
    return {
        "kind": kind, "group": group, "count": count,
        "embree_rays_per_second": count / float(np.median(embree_seconds)),
        "ours_rays_per_second": count / float(np.median(ours_seconds)),
        "ratio": float(np.median(ratios)), "ratio_min": min(ratios),
        "ratio_max": max(ratios), "ratios": ratios,
        "binding_seconds": binding_seconds,
        "embree_less_binding_rays_per_second": count / float(np.median(traced)),
        "ratio_less_binding": float(np.median(net_ratios)),
        "ratio_less_binding_min": min(net_ratios), "ratio_less_binding_max": max(net_ratios),
        "differ": differ, "embree_at_t0": at_zero, "same_t_other_primitive": other,
    }


def print_row(r):
    print(f"{r['kind']:<8} {r['group']:<11} {r['count']:>9} "
          f"{r['embree_rays_per_second'] / 1e6:>12.2f} {r['ours_rays_per_second'] / 1e6:>10.2f} "
          f"{r['ratio']:>12.3f} {r['ratio_min']:>5.2f}-{r['ratio_max']:<5.2f} "
          f"{r['embree_less_binding_rays_per_second'] / 1e6:>22.2f} "
          f"{r['ratio_less_binding']:>12.3f} ({r['ratio_less_binding_min']:.2f}-"
          f"{r['ratio_less_binding_max']:.2f}) {r['differ']:>7} "
          f"{r['embree_at_t0']:>11} "
          f"{r['same_t_other_primitive']:>19}")


if __name__ == "__main__":
    main()
