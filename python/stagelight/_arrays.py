"""Float32 images between NumPy and the engine's raw buffers (width x height x 3, rows in
order, native byte order)."""

from __future__ import annotations

from typing import Any, Tuple

import numpy as np


def view(raw: Any, width: int, height: int) -> np.ndarray:
    """A height x width x 3 view of a buffer the engine filled: no copy."""
    return np.frombuffer(raw, dtype=np.float32).reshape(height, width, 3)


def float_bytes(image: Any, what: str) -> Tuple[bytes, int, int]:
    """An image's float32 bytes, width and height; anything but height x width x 3 raises."""
    a = np.ascontiguousarray(image, dtype=np.float32)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"{what}: an image is height x width x 3, not {a.shape}")
    return a.tobytes(), a.shape[1], a.shape[0]
