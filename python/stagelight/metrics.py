"""Error of an image against a reference, measured by the engine's own code (the numbers
``stagelight diff`` and ``stagelight compare`` print; ../shared/METRICS.md defines them)."""

from __future__ import annotations

from typing import Any, Dict

from . import _native
from ._arrays import float_bytes

__all__ = ["errors", "relmse", "rmse", "mae"]


def errors(image: Any, reference: Any) -> Dict[str, Any]:
    """relmse, rmse, mae, and both images' channel means. Images of different sizes, or with
    NaN or infinite values, raise ValueError."""
    a, w, h = float_bytes(image, "image")
    b, rw, rh = float_bytes(reference, "reference")
    if (w, h) != (rw, rh):
        raise ValueError(f"images differ in size: {w}x{h} against a reference of {rw}x{rh}")
    return dict(_native.metrics(a, b, w, h))


def relmse(image: Any, reference: Any) -> float:
    """Mean over pixels and channels of (x - r)^2 / (r^2 + 0.01)."""
    return float(errors(image, reference)["relmse"])


def rmse(image: Any, reference: Any) -> float:
    return float(errors(image, reference)["rmse"])


def mae(image: Any, reference: Any) -> float:
    return float(errors(image, reference)["mae"])
