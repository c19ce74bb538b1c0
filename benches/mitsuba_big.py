#!/usr/bin/env python3
"""Mitsuba 3 on the big scenes that `stagelight bench --big DIR` writes (DIR/NAME/NAME.xml: the
same PLY files as NAME.ron), for a side-by-side throughput table. Not part of the build or the
tests: it needs Mitsuba 3 (see ../shared/mitsuba/README.md for its set-up).

Usage: python mitsuba_big.py DIR/NAME/NAME.xml [VARIANT] [THREADS] [SPP] [RUNS]
       (defaults: llvm_ad_rgb 2 32 3)

Prints the scene's load time (mi.load_file: the PLY files read and Embree's tree built), the
tree build alone as Mitsuba logs it ("Embree ready. (took ...)"), a warm-up render (which
includes the JIT compilation of the llvm variants) and RUNS timed renders with their median
samples/s (pixels x spp / seconds)."""
import os, statistics, sys, time
import mitsuba as mi, drjit as dr

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
