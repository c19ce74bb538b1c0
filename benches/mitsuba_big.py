#!/usr/bin/env python3
"""Mitsuba 3 on the big scenes that `stagelight bench --big DIR` writes (DIR/NAME/NAME.xml: the
same PLY files as NAME.ron), for a side-by-side throughput table. Not part of the build or the
tests: it needs Mitsuba 3 (see ../shared/mitsuba/README.md for its set-up).

Usage: python mitsuba_big.py DIR/NAME/NAME.xml [VARIANT] [THREADS] [SPP] [RUNS]
       (defaults: llvm_ad_rgb 2 32 3)
       python mitsuba_big.py --rays DIR/NAME/NAME.xml [VARIANT] [THREADS]

Prints the scene's load time (mi.load_file: the PLY files read and Embree's tree built), the
tree build alone as Mitsuba logs it ("Embree ready. (took ...)"), a warm-up render (which
includes the JIT compilation of the llvm variants) and RUNS timed renders with their median
samples/s (pixels x spp / seconds).

With --rays: Embree's closest-hit (`ray_intersect_preliminary`) and any-hit (`ray_test`) rays/s
on the million incoherent rays of `BVH_BIG=DIR cargo bench --bench bvh_traversal` (the same
splitmix64 numbers, in the scene's bounds), each the best of 5 passes after a warm-up (which
compiles the kernel), with the hit counts to check that both trace the same rays."""
import os, statistics, sys, time
import mitsuba as mi, drjit as dr

rays_mode = sys.argv[1] == '--rays'
if rays_mode:
    del sys.argv[1]
scene_file = sys.argv[1]
variant = sys.argv[2] if len(sys.argv) > 2 else 'llvm_ad_rgb'
threads = int(sys.argv[3]) if len(sys.argv) > 3 else 2
spp = int(sys.argv[4]) if len(sys.argv) > 4 else 32
runs = int(sys.argv[5]) if len(sys.argv) > 5 else 3
mi.set_variant(variant)
dr.set_thread_count(threads)


class Capture(mi.Appender):
    """Keeps Mitsuba's log lines (the tree build's time among them)."""
    def __init__(self):
        super().__init__()
        self.lines = []

    def append(self, level, text):
        self.lines.append(text)

    def log_progress(self, progress, name, formatted, eta, ptr=None):
        pass


log = Capture()
logger = mi.logger()
logger.clear_appenders()
logger.add_appender(log)
logger.set_log_level(mi.LogLevel.Info)

t = time.perf_counter()
scene = mi.load_file(scene_file, spp=spp)
if rays_mode:
    import numpy as np
    n = 1 << 20

    def uniform(k):
        """splitmix64 of i * 8 + k, its top 24 bits over 2^24 (as bvh_traversal.rs)."""
        with np.errstate(over='ignore'):
            z = np.arange(n, dtype=np.uint64) * np.uint64(8) + np.uint64(k)
            z = z + np.uint64(0x9e3779b97f4a7c15)
            z = (z ^ (z >> np.uint64(30))) * np.uint64(0xbf58476d1ce4e5b9)
            z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94d049bb133111eb)
            z = z ^ (z >> np.uint64(31))
        return ((z >> np.uint64(40)).astype(np.float32) * np.float32(2.0 ** -24))

    bbox = scene.bbox()
    lo, hi = np.array(bbox.min, dtype=np.float32), np.array(bbox.max, dtype=np.float32)
    o = [lo[a] + (hi[a] - lo[a]) * uniform(a) for a in range(3)]
    z = 1.0 - 2.0 * uniform(3)
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = np.float32(2.0 * np.pi) * uniform(4)
    d = [r * np.cos(phi), r * np.sin(phi), z]
    t_max = np.float32(0.5) * np.linalg.norm(hi - lo) * uniform(5)
    closest_ray = mi.Ray3f(mi.Point3f(*o), mi.Vector3f(*d))
    any_ray = mi.Ray3f(mi.Point3f(*o), mi.Vector3f(*d), mi.Float(t_max), 0.0, mi.Color0f())
    dr.eval(closest_ray, any_ray)

    def best(f):
        counts, times = None, []
        for _ in range(6):
            t = time.perf_counter()
            count = f()
            times.append(time.perf_counter() - t)
            counts = count
        return n / min(times[1:]) * 1e-6, counts

    closest, closest_hits = best(lambda: int(dr.count(
        scene.ray_intersect_preliminary(closest_ray).is_valid())[0]))
    anyhit, any_hits = best(lambda: int(dr.count(scene.ray_test(any_ray))[0]))
    built = [l.strip().split("(")[-1].rstrip(")") for l in log.lines if "ready" in l]
    print(f'{os.path.basename(scene_file)} {variant} threads={dr.thread_count()} '
          f'tree="{built[-1] if built else "?"}" closest {closest:.2f} Mrays/s '
          f'({closest_hits} hits), any {anyhit:.2f} Mrays/s ({any_hits} hits)', flush=True)
    sys.exit(0)
load_s = time.perf_counter() - t
built = [l.strip().split("(")[-1].rstrip(")") for l in log.lines if "ready" in l]
film = scene.sensors()[0].film().crop_size()
pixels = int(film[0]) * int(film[1])
t = time.perf_counter()
mean = mi.render(scene, spp=spp, seed=1000).numpy().mean((0, 1))
warm_s = time.perf_counter() - t
rates = []
for run in range(runs):
    t = time.perf_counter()
    image = mi.render(scene, spp=spp, seed=run)
    image.numpy()  # waits for the render
    dt = time.perf_counter() - t
    rates.append(pixels * spp / dt)
print(f'{os.path.basename(scene_file)} {variant} threads={dr.thread_count()} spp={spp} '
      f'load_s={load_s:.3f} tree="{built[-1] if built else "?"}" warmup_s={warm_s:.3f} '
      f'samples_per_s median={statistics.median(rates):.4g} min={min(rates):.4g} '
      f'max={max(rates):.4g} mean_rgb={mean}', flush=True)
