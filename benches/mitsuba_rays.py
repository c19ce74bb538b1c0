#!/usr/bin/env python3
"""Mitsuba 3's own ray tracing on the rays a `stagelight rays` folder holds (issue 44): where
benches/embree_rays.py times Embree one ray at a time through embreex, this times the whole
batch through Mitsuba (`Scene.ray_intersect_preliminary` and `Scene.ray_test`, which the llvm
variants hand to Embree in packets of their vector width), so it says how fast the tracing
inside Mitsuba's path tracer is on the same rays. Not part of the build or the tests: it
needs Mitsuba 3 (../shared/mitsuba/README.md) and the scene as Mitsuba XML (the big scenes'
DIR/NAME/NAME.xml from `stagelight bench --big DIR`).

Usage: python mitsuba_rays.py SCENE.xml RAYS_DIR [THREADS] [VARIANT]
       (defaults: 1 thread, llvm_ad_rgb)

    stagelight rays DIR/big_1m/big_1m.ron --out rays/big_1m --spp 4
    python benches/mitsuba_rays.py DIR/big_1m/big_1m.xml rays/big_1m 1
    stagelight bench --rays rays/big_1m --threads 1

Each group (all rays, bounce 0, bounce 1) is traced four times and the median of the last
three is printed as rays/s; where RAYS_DIR holds the hits.npy `stagelight bench --rays` wrote,
also how many answers differ from stagelight's (a closest hit: one tracer hits and the other
does not, or the distances differ by more than a relative 1e-4; a shadow ray: one finds it
occluded and the other does not). Every ray starts a hundred-thousandth of the scene's diagonal
along its direction (its t_max shortened as much), as in embree_rays.py: Mitsuba, like
embreex, would otherwise find a ray leaving a surface at t = 0 on that surface."""
import json, sys, time
import numpy as np
import mitsuba as mi
import drjit as dr

scene_file, ray_dir = sys.argv[1], sys.argv[2]
threads = int(sys.argv[3]) if len(sys.argv) > 3 else 1
variant = sys.argv[4] if len(sys.argv) > 4 else 'llvm_ad_rgb'
mi.set_variant(variant)
dr.set_thread_count(threads)
scene = mi.load_file(scene_file)
bounds = scene.bbox()
offset = 1e-5 * float(dr.norm(bounds.extents()))
meta = json.load(open(f'{ray_dir}/rays.json'))
try:
    ours = np.load(f'{ray_dir}/hits.npy')['t']
except FileNotFoundError:
    ours = None


def rays_of(columns):
    """Mitsuba rays from rows of (origin, t_min, direction, t_max); directions need not be
    unit (shadow rays run to t_max = 1 - epsilon towards their light point)."""
    length = np.linalg.norm(columns[:, 4:7], axis=1)
    unit = columns[:, 4:7] / length[:, None]
    origin = columns[:, 0:3] + unit * offset
    t_max = np.where(np.isinf(columns[:, 7]), 3.0e38, columns[:, 7] - offset / length)
    ray = mi.Ray3f(mi.Point3f(*[mi.Float(np.ascontiguousarray(origin[:, i])) for i in range(3)]),
                   mi.Vector3f(*[mi.Float(np.ascontiguousarray(columns[:, 4 + i]))
                                 for i in range(3)]))
    # Set apart: Ray3f(o, d, x) would read x as the ray's time.
    ray.maxt = mi.Float(t_max.astype(np.float32))
    dr.eval(ray)
    return ray


print(f'{scene_file}: {variant}, {dr.thread_count()} thread(s); median of 3 runs after one')
for kind in ('closest', 'shadow'):
    rows = np.load(f'{ray_dir}/{kind}.npy')
    # hits.npy: the closest-hit rays' answers, then the shadow rays'.
    first = 0 if kind == 'closest' else len(np.load(f'{ray_dir}/closest.npy', mmap_mode='r'))
    groups = [('all', 0, rows)] + [(f"bounce {g['bounce']}", g['first'],
                                    rows[g['first']:g['first'] + g['count']])
                                   for g in meta[kind] if g['bounce'] <= 1]
    for name, start, part in groups:
        ray = rays_of(part)
        times = []
        for _ in range(4):
            began = time.perf_counter()
            if kind == 'closest':
                answer = scene.ray_intersect_preliminary(ray).t
            else:
                answer = scene.ray_test(ray)
            dr.eval(answer)
            times.append(time.perf_counter() - began)
        median = sorted(times[1:])[1]
        differ = ''
        if ours is not None:
            theirs = np.array(answer)
            mine = ours[first + start:first + start + len(part)]
            if kind == 'closest':
                length = np.linalg.norm(part[:, 4:7], axis=1)
                theirs = np.where(np.isfinite(theirs), theirs + offset / length, np.inf)
                both = np.isfinite(theirs) & np.isfinite(mine)
                with np.errstate(invalid='ignore'):
                    apart = np.abs(theirs - mine) > 1e-4 * np.maximum(np.abs(mine), 1e-30)
                count = int(np.sum(np.isfinite(theirs) != np.isfinite(mine)) + np.sum(both & apart))
            else:
                count = int(np.sum(theirs.astype(bool) != np.isfinite(mine)))
            differ = f'  {count} differ'
        print(f'{kind:8} {name:10} {len(part):8} rays {len(part) / median / 1e6:7.2f} M rays/s'
              f'{differ}', flush=True)
