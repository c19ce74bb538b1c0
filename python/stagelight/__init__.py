"""stagelight from Python: load a scene once, render it with any integrator, compare
integrators against a reference, and read every system's timings, as NumPy arrays and rows.

    import stagelight
    scene = stagelight.load("scenes/cornell_box.ron")
    r = stagelight.render(scene, "bdpt", spp=16)
    r.image            # float32 array, height x width x 3 (linear RGB)
    print(r.stats)     # per-system seconds, items and shares; samples/s, rays/s

Keyword options are the command line's, `-` written `_` (``max_depth=5`` is
``--max-depth 5``); ``stagelight render --help`` lists them. Errors carry the command
line's messages. The GIL is released while rendering; Ctrl-C stops a render after the
passes in flight and raises KeyboardInterrupt whose ``.partial`` is the finished passes'
`Render`.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native, metrics
from ._arrays import float_bytes as _float_bytes
from ._arrays import view as _image
from ._native import RenderError, Scene, SceneError

__all__ = [
    "Scene",
    "SceneError",
    "RenderError",
    "Render",
    "Reference",
    "Stats",
    "SystemTime",
    "load",
    "render",
    "reference",
    "compare",
    "integrators",
    "read_exr",
    "write_exr",
    "metrics",
]

PathLike = Union[str, "os.PathLike[str]"]

# Options that write files: the Python functions return their results instead.
_FILE_OPTIONS = {"output", "quiet", "shard", "pass_range"}


def _define_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def load(path: PathLike, **defines: Any) -> Scene:
    """Loads a RON or Mitsuba 3 XML scene and prepares it for rendering.

    Keyword arguments set the XML's ``$name`` parameters, as ``-D name=value`` does on the
    command line (``load("scene.xml", spp=64)``). The scene's warnings (dropped triangles,
    unused materials) are issued as Python warnings. Raises `SceneError` with the command
    line's message (file, line and column) for a bad scene.
    """
    scene = _native.load(os.fspath(path), [(k, _define_value(v)) for k, v in defines.items()])
    for w in scene.warnings:
        warnings.warn(w, stacklevel=2)
    return scene


def _as_scene(scene: Union[Scene, PathLike]) -> Scene:
    return scene if isinstance(scene, Scene) else load(scene)


def _arguments(options: Mapping[str, Any], function: str) -> List[str]:
    """Keyword options as command-line arguments: ``max_depth=5`` -> ``--max-depth 5``."""
    args: List[str] = []
    for key, value in options.items():
        if key in _FILE_OPTIONS:
            raise TypeError(
                f"{function}() got the keyword argument '{key}', which the command line uses "
                "to write files: the Python functions return their results"
            )
        if value is None or value is False:
            continue
        flag = "--" + key.replace("_", "-")
        if value is True:
            args.append(flag)
        elif isinstance(value, (list, tuple)):
            args += [flag, ",".join(str(v) for v in value)]
        else:
            args += [flag, str(value)]
    return args


@dataclass(frozen=True)
class SystemTime:
    """One system's share of a render: its wall seconds (summed over its runs), the share of
    all systems' time, its runs, and the items it took and emitted."""

    name: str
    seconds: float
    share: float
    runs: int
    taken: int
    emitted: int


@dataclass(frozen=True)
class Stats:
    """A render's timings: per system, and the render's throughput."""

    systems: Tuple[SystemTime, ...]
    seconds: float
    samples: int
    closest_rays: int
    shadow_rays: int
    notes: Dict[str, str] = field(default_factory=dict)

    @property
    def samples_per_second(self) -> float:
        return self.samples / max(self.seconds, 1e-9)

    @property
    def rays_per_second(self) -> float:
        return (self.closest_rays + self.shadow_rays) / max(self.seconds, 1e-9)

    def __getitem__(self, name: str) -> SystemTime:
        for s in self.systems:
            if s.name == name:
                return s
        raise KeyError(name)

    def rows(self) -> List[Dict[str, Any]]:
        """The systems as rows (dicts), for a table or a pandas DataFrame."""
        return [s.__dict__.copy() for s in self.systems]

    def __str__(self) -> str:
        lines = [
            f"{self.samples_per_second / 1e6:.3f} M samples/s, "
            f"{self.rays_per_second / 1e6:.3f} M rays/s over {self.seconds:.3f} s",
            f"{'system':<32} {'seconds':>9} {'share':>7} {'runs':>6} {'taken':>12} {'emitted':>12}",
        ]
        for s in self.systems:
            lines.append(
                f"{s.name:<32} {s.seconds:>9.4f} {100 * s.share:>6.1f}% {s.runs:>6} "
                f"{s.taken:>12} {s.emitted:>12}"
            )
        return "\n".join(lines)


@dataclass(frozen=True)
class Render:
    """A finished (or interrupted) render.

    ``image`` is float32 linear RGB, height x width x 3, the image the command line writes as
    its EXR; ``layers`` holds bdpt's and mmlt's strategy images (``strategy_images=True``),
    ``variance`` pt's per-pixel sample variance (``variance=True``); ``report`` is the text
    ``stagelight render`` prints.
    """

    image: np.ndarray
    stats: Stats
    report: str
    passes: int
    samples: int
    seconds: float
    interrupted: bool
    nonfinite: int
    nonfinite_splats: int
    layers: Dict[str, np.ndarray]
    variance: Optional[np.ndarray]

    @classmethod
    def _from(cls, d: Dict[str, Any]) -> "Render":
        w, h = d["width"], d["height"]
        stats = Stats(
            systems=tuple(SystemTime(**s) for s in d["systems"]),
            seconds=d["seconds"],
            samples=d["samples"],
            closest_rays=d["closest_rays"],
            shadow_rays=d["shadow_rays"],
            notes=dict(d["notes"]),
        )
        variance = d["variance"]
        return cls(
            image=_image(d["image"], w, h),
            stats=stats,
            report=d["report"],
            passes=d["passes"],
            samples=d["samples"],
            seconds=d["seconds"],
            interrupted=d["interrupted"],
            nonfinite=d["nonfinite"],
            nonfinite_splats=d["nonfinite_splats"],
            layers={k: _image(v, w, h) for k, v in d["layers"].items()},
            variance=None if variance is None else _image(variance, w, h),
        )

    def __repr__(self) -> str:
        h, w, _ = self.image.shape
        return (
            f"Render({w}x{h}, {self.passes} passes, {self.seconds:.3f} s"
            f"{', interrupted' if self.interrupted else ''})"
        )


def _reraise_with_partial(e: BaseException, convert: Any) -> None:
    partial = getattr(e, "partial", None)
    try:
        e.partial = convert(partial) if isinstance(partial, dict) else None  # type: ignore[attr-defined]
    except AttributeError:
        pass


def render(
    scene: Union[Scene, PathLike],
    integrator: str = "pt",
    spp: Optional[int] = None,
    time: Optional[float] = None,
    seed: int = 0,
    threads: Optional[int] = None,
    **options: Any,
) -> Render:
    """Renders a scene; returns the `Render`.

    ``spp`` samples per pixel (default: the Mitsuba file's sample count, else 64), or ``time``
    seconds of whole passes. Any other ``render`` option of the command line by its name with
    ``_`` for ``-`` (``max_depth=8``, ``sampler="sobol"``, ``kernel="megakernel"``,
    ``photons_per_pass=100000``, ``large_step=0.3``, ...); ``strategy_images=True`` (bdpt,
    mmlt) and ``variance=True`` (pt) return those images in ``layers`` and ``variance``. The
    same scene, seed and options give the command line's image bit for bit.
    """
    scene = _as_scene(scene)
    options = dict(options)
    # These write files on the command line; here their images come back in the Render.
    args = []
    if options.pop("strategy_images", False):
        args += ["--strategy-images", "strategies"]
    if options.pop("variance", False):
        args += ["--variance", "variance.exr"]
    args += _arguments(
        dict(integrator=integrator, seed=seed, spp=spp, time=time, threads=threads, **options),
        "render",
    )
    try:
        return Render._from(_native.render(scene, args))
    except KeyboardInterrupt as e:
        _reraise_with_partial(e, Render._from)
        raise


@dataclass(frozen=True)
class Reference:
    """A checkpointed reference: its image (as its EXR holds it), passes over all its runs,
    render seconds over all its runs, the EXR's path and the command line's report."""

    image: Optional[np.ndarray]
    passes: int
    seconds: float
    interrupted: bool
    path: str
    report: str

    @classmethod
    def _from(cls, d: Dict[str, Any]) -> "Reference":
        image = _image(d["image"], d["width"], d["height"]) if "image" in d else None
        return cls(image, d["passes"], d["seconds"], d["interrupted"], d["path"], d["report"])


def reference(
    scene: Union[Scene, PathLike],
    spp: Optional[int] = None,
    *,
    checkpoint: PathLike,
    time: Optional[float] = None,
    integrator: str = "pt",
    seed: Optional[int] = None,
    threads: Optional[int] = None,
    **options: Any,
) -> Reference:
    """Makes, resumes or extends a long reference render, as ``stagelight reference`` does.

    ``checkpoint`` is the reference's EXR; its checkpoint (``.exr.checkpoint``) and PNG lie
    beside it, and a later call with a larger ``spp`` (or ``time``, total render seconds)
    continues from the passes it holds. Ctrl-C keeps the finished passes on disk.
    """
    scene = _as_scene(scene)
    args = ["-o", os.fspath(checkpoint)] + _arguments(
        dict(integrator=integrator, spp=spp, time=time, seed=seed, threads=threads, **options),
        "reference",
    )
    try:
        return Reference._from(_native.reference(scene, args))
    except KeyboardInterrupt as e:
        _reraise_with_partial(e, Reference._from)
        raise


def compare(
    scene: Union[Scene, PathLike],
    integrators: Sequence[str],
    budgets: Sequence[float],
    reference: Union[np.ndarray, PathLike],
    unit: str = "seconds",
    seed: int = 0,
    threads: Optional[int] = None,
    images: bool = False,
    **options: Any,
) -> Any:
    """Renders each integrator at each budget (``unit`` "seconds" or "spp") and measures it
    against ``reference`` (an array, or an EXR's path), as ``stagelight compare`` does.

    Returns one row per run, in run order (integrator, budget, unit, wall, cpu, samples,
    passes, closest_rays, shadow_rays, photons, relmse, rmse, mae, efficiency; ``image`` too
    with ``images=True``): a pandas DataFrame when pandas is installed, else a list of dicts.
    """
    scene = _as_scene(scene)
    ref = read_exr(reference) if not isinstance(reference, np.ndarray) else reference
    ref_bytes, _, _ = _float_bytes(ref, "reference")
    args = _arguments(
        dict(
            integrators=list(integrators),
            budgets=[repr(float(b)) for b in budgets],
            budget_unit=unit,
            seed=seed,
            threads=threads,
            **options,
        ),
        "compare",
    )
    width, height = scene.size

    def rows_of(raw: List[Dict[str, Any]]) -> Any:
        rows = []
        for r in raw:
            row = dict(r)
            image = row.pop("image")
            if images:
                row["image"] = _image(image, width, height)
            rows.append(row)
        try:
            import pandas  # noqa: F401  (optional)
        except ImportError:
            return rows
        return pandas.DataFrame(rows)

    try:
        return rows_of(_native.compare(scene, ref_bytes, args))
    except KeyboardInterrupt as e:
        _reraise_with_partial(e, lambda d: rows_of(d["rows"]))
        raise


def integrators(scene: Optional[Union[Scene, PathLike]] = None) -> List[Dict[str, Any]]:
    """The integrators built in, in the order reports list them: name, description,
    unbiased, resumes (whether a reference can continue it) and its own options (Python
    names). With a scene, each also has its ``graph`` for that scene."""
    out = []
    loaded = None if scene is None else _as_scene(scene)
    for info in _native.integrators():
        info = dict(info)
        info["options"] = [o.lstrip("-").replace("-", "_") for o in info["options"]]
        if loaded is not None:
            info["graph"] = loaded.graph(info["name"])
        out.append(info)
    return out


def read_exr(path: PathLike) -> np.ndarray:
    """An EXR's RGB as float32, height x width x 3."""
    raw, width, height = _native.read_exr(os.fspath(path))
    return _image(raw, width, height)


def write_exr(path: PathLike, image: Any) -> None:
    """Writes a height x width x 3 image as a float32 EXR."""
    raw, width, height = _float_bytes(image, "image")
    _native.write_exr(os.fspath(path), raw, width, height)
