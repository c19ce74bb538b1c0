"""The Python module against the command line and against independent checks.

The command line's binary comes from $STAGELIGHT_BIN, else target/release/stagelight
(`cargo build --release`); .ci/run sets it to the test profile's binary, which the suite built.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import stagelight

ROOT = Path(__file__).resolve().parents[2]
CORNELL = ROOT / "scenes" / "cornell_box.ron"
ROOM = ROOT / "tests" / "scenes" / "mitsuba" / "materials_room.xml"


def cli_binary() -> Path:
    path = Path(os.environ.get("STAGELIGHT_BIN", ROOT / "target" / "release" / "stagelight"))
    if not path.is_file():
        pytest.fail(f"no stagelight binary at {path}: run `cargo build --release` or set STAGELIGHT_BIN")
    return path


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(cli_binary()), *args], capture_output=True, text=True, cwd=ROOT, timeout=600
    )


def cli_error(*args: str) -> str:
    """The command line's message for a refused command: its stderr's first line, after
    'error: ' (exit 1)."""
    done = cli(*args)
    assert done.returncode != 0, done.stdout
    first = done.stderr.strip().splitlines()[0]
    assert first.startswith("error: "), done.stderr
    return first[len("error: ") :]


def small_room(width: int = 16, height: int = 12) -> stagelight.Scene:
    return stagelight.load(ROOM, width=width, height=height)


# Options that keep each integrator's one-pass render to a fraction of a second.
FAST = {
    "pm": {"photons": 20000, "k": 16},
    "ppm": {"photons_per_pass": 5000},
    "sppm": {"photons_per_pass": 5000},
    "mlt": {"direct_spp": 1},
}


@pytest.mark.parametrize(
    "scene, defines, integrator, spp, options",
    [
        (CORNELL, {}, "pt", 2, {}),
        (CORNELL, {}, "pt", 2, {"kernel": "megakernel", "sampler": "sobol"}),
        (ROOM, {"width": 40, "height": 30}, "bdpt", 2, {"max_depth": 4}),
        (ROOM, {"width": 40, "height": 30}, "sppm", 2, {"photons_per_pass": 20000}),
        (ROOM, {"width": 40, "height": 30}, "mmlt", 2, {}),
    ],
)
def test_render_equals_the_cli_exr_bit_for_bit(tmp_path, scene, defines, integrator, spp, options):
    out = tmp_path / "cli.exr"
    args = ["render", str(scene), "--integrator", integrator, "--spp", str(spp), "--seed", "7"]
    args += ["--threads", "2", "-o", str(out), "--quiet"]
    for k, v in defines.items():
        args += ["-D", f"{k}={v}"]
    for k, v in options.items():
        args += ["--" + k.replace("_", "-"), str(v)]
    done = cli(*args)
    assert done.returncode == 0, done.stderr
    expected = stagelight.read_exr(out)
    # One thread here, two there: the image does not depend on the thread count.
    got = stagelight.render(
        stagelight.load(scene, **defines), integrator, spp=spp, seed=7, threads=1, **options
    )
    assert got.image.dtype == np.float32
    assert got.image.shape == expected.shape
    assert got.image.tobytes() == expected.tobytes()


def test_every_integrator_renders_and_reports_its_systems():
    scene = small_room()
    names = [i["name"] for i in stagelight.integrators()]
    assert names[:3] == ["pt", "bdpt", "vcm"] and len(names) == 10
    for name in names:
        r = stagelight.render(scene, name, spp=1, threads=2, **FAST.get(name, {}))
        assert r.image.shape == (12, 16, 3), name
        assert np.isfinite(r.image).all(), name
        assert r.image.mean() > 0, name
        assert r.passes >= 1 and r.samples > 0, name
        assert f"with {name} at 16x12" in r.report, name
        assert r.stats.systems and all(s.seconds >= 0 for s in r.stats.systems), name
        assert abs(sum(s.share for s in r.stats.systems) - 1) < 1e-6, name
        assert r.stats.samples_per_second > 0, name


def test_integrators_list_their_options_and_graphs():
    infos = {i["name"]: i for i in stagelight.integrators(small_room())}
    assert "strategy_images" in infos["bdpt"]["options"]
    assert "photons_per_pass" in infos["sppm"]["options"]
    assert infos["pt"]["unbiased"] and not infos["sppm"]["unbiased"]
    assert "trace" in infos["pt"]["graph"]


def test_per_system_timings_and_layers():
    scene = small_room()
    r = stagelight.render(scene, "bdpt", spp=2, threads=2, strategy_images=True)
    assert r.stats["trace_closest"].taken > 0
    assert "s1_t1" in r.layers or any(k.startswith("s") for k in r.layers)
    # The strategy images add up to the image (bdpt writes every weighted contribution).
    total = sum(layer.astype(np.float64) for layer in r.layers.values())
    assert np.allclose(total, r.image, rtol=1e-3, atol=1e-4)
    v = stagelight.render(scene, "pt", spp=4, threads=2, variance=True)
    assert v.variance is not None and v.variance.shape == v.image.shape
    assert (v.variance >= 0).all()


def test_bad_scenes_raise_the_cli_message(tmp_path):
    bad_ron = tmp_path / "bad.ron"
    bad_ron.write_text("(camera: (position: (0, 0, 1),\n  fov: oops))\n")
    bad_xml = tmp_path / "bad.xml"
    bad_xml.write_text('<scene version="3.0.0">\n  <bsdf type="hair"/>\n</scene>\n')
    for bad in (bad_ron, bad_xml, tmp_path / "missing.xml"):
        expected = cli_error("render", str(bad), "-o", str(tmp_path / "x.exr"))
        with pytest.raises(stagelight.SceneError) as caught:
            stagelight.load(bad)
        assert str(caught.value) == expected
        assert isinstance(caught.value, ValueError)


def test_bad_arguments_raise_the_cli_message(tmp_path):
    scene = stagelight.load(CORNELL)
    out = ["-o", str(tmp_path / "x.exr")]
    cases = [
        ({"spp": 0}, ["--spp", "0"], ValueError),
        ({"integrator": "ptt"}, ["--integrator", "ptt"], ValueError),
        ({"strategy_images": True}, ["--strategy-images", str(tmp_path)], ValueError),
        ({"kernel": "megakernel", "integrator": "bdpt"}, ["--kernel", "megakernel", "--integrator", "bdpt"], ValueError),
        ({"large_step": 2}, ["--large-step", "2"], ValueError),
        ({"no_such_option": 3}, ["--no-such-option", "3"], TypeError),
    ]
    for kwargs, args, kind in cases:
        expected = cli_error("render", str(CORNELL), *args, *out)
        with pytest.raises(kind) as caught:
            stagelight.render(scene, **kwargs)
        assert str(caught.value) == expected, kwargs
    with pytest.raises(TypeError):
        stagelight.render(scene, output="x.exr")


def test_keyboard_interrupt_stops_within_two_seconds_with_the_finished_passes():
    scene = small_room(32, 24)
    sent = []

    def interrupt():
        sent.append(time.monotonic())
        os.kill(os.getpid(), signal.SIGINT)

    timer = threading.Timer(1.0, interrupt)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt) as caught:
            stagelight.render(scene, "pt", time=60, threads=2)
        stopped = time.monotonic()
    finally:
        timer.cancel()
    assert sent and stopped - sent[0] < 2.0
    partial = caught.value.partial
    assert isinstance(partial, stagelight.Render)
    assert partial.interrupted and partial.passes >= 1
    assert partial.image.shape == (24, 32, 3) and partial.image.mean() > 0


def test_the_gil_is_released_while_rendering():
    scene = small_room(32, 24)
    counts = [0]
    running = threading.Event()
    running.set()

    def count():
        while running.is_set():
            counts[0] += 1

    t = threading.Thread(target=count)
    t.start()
    try:
        before = counts[0]
        stagelight.render(scene, "pt", time=1.0, threads=1)
        during = counts[0] - before
    finally:
        running.clear()
        t.join()
    # A thread that held the GIL for the render would leave the counter nearly still.
    assert during > 100_000, during


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def test_memory_does_not_grow_with_renders():
    scene = small_room()
    for _ in range(20):
        stagelight.render(scene, "pt", spp=1, threads=2)
    after_20 = rss_bytes()
    for _ in range(180):
        stagelight.render(scene, "pt", spp=1, threads=2)
    after_200 = rss_bytes()
    assert after_200 - after_20 < 10 * 2**20, (after_20, after_200)


def test_metrics_are_the_definitions():
    rng = np.random.default_rng(3)
    ref = rng.random((9, 7, 3), dtype=np.float32)
    img = ref + rng.normal(0, 0.1, ref.shape).astype(np.float32)
    x, r = img.astype(np.float64), ref.astype(np.float64)
    m = stagelight.metrics.errors(img, ref)
    assert m["relmse"] == pytest.approx(np.mean((x - r) ** 2 / (r**2 + 0.01)), rel=1e-9)
    assert m["rmse"] == pytest.approx(np.sqrt(np.mean((x - r) ** 2)), rel=1e-9)
    assert m["mae"] == pytest.approx(np.mean(np.abs(x - r)), rel=1e-9)
    with pytest.raises(ValueError):
        stagelight.metrics.relmse(img[:5], ref)
    bad = img.copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        stagelight.metrics.relmse(bad, ref)


def test_reference_resumes_from_its_checkpoint(tmp_path):
    scene = small_room()
    path = tmp_path / "ref.exr"
    first = stagelight.reference(scene, spp=2, checkpoint=path, threads=2)
    assert first.passes == 2 and "made with" in first.report
    second = stagelight.reference(scene, spp=4, checkpoint=path, threads=2)
    assert second.passes == 4 and "resumed from 2 spp" in second.report
    assert second.image.tobytes() == stagelight.read_exr(path).tobytes()
    # A reference resumed to 4 passes is the reference made with 4 at once.
    whole = stagelight.reference(scene, spp=4, checkpoint=tmp_path / "whole.exr", threads=2)
    assert whole.image.tobytes() == second.image.tobytes()


def test_compare_measures_each_run_against_the_reference():
    scene = small_room()
    ref = stagelight.render(scene, "pt", spp=64, seed=99, threads=2).image
    rows = stagelight.compare(
        scene, ["pt", "bdpt"], [1, 4], ref, unit="spp", threads=2, images=True
    )
    if not isinstance(rows, list):
        rows = rows.to_dict("records")
    assert [(r["integrator"], r["budget"]) for r in rows] == [
        ("pt", 1.0), ("pt", 4.0), ("bdpt", 1.0), ("bdpt", 4.0)
    ]
    for r in rows:
        assert r["relmse"] == pytest.approx(stagelight.metrics.relmse(r["image"], ref), rel=1e-12)
    # More samples, less error (pt: 4 spp against 1 at this noise level).
    assert rows[1]["relmse"] < rows[0]["relmse"]


def test_images_round_trip_through_exr(tmp_path):
    img = np.linspace(0, 4, 5 * 4 * 3, dtype=np.float32).reshape(5, 4, 3)
    stagelight.write_exr(tmp_path / "a.exr", img)
    assert stagelight.read_exr(tmp_path / "a.exr").tobytes() == img.tobytes()


def test_the_docs_example_reruns_the_figure_data(tmp_path):
    example = ROOT / "docs" / "examples" / "error_vs_time.py"
    done = subprocess.run(
        [sys.executable, str(example), str(ROOM), "0.1,0.2", "16"],
        capture_output=True, text=True, cwd=tmp_path, timeout=300,
    )
    assert done.returncode == 0, done.stderr
    lines = [l for l in done.stdout.splitlines() if "relMSE" in l]
    assert len(lines) == 10, done.stdout
    assert {l.split()[0] for l in lines} == {"pt", "bdpt", "pm", "ppm", "mlt"}
    assert (tmp_path / "reference" / "example.exr").is_file()
