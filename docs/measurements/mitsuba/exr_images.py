"""read(PATH): an EXR's RGB as a float64 H x W x 3 array (RGB, RGBA or separate R, G, B
channels), for the measurement scripts beside this file."""
import numpy as np, OpenEXR


def read(p):
    with OpenEXR.File(p) as f:
        ch = f.channels()
        key = "RGB" if "RGB" in ch else ("RGBA" if "RGBA" in ch else None)
        if key:
            return np.asarray(ch[key].pixels, dtype=np.float64)[..., :3]
        return np.stack([np.asarray(ch[c].pixels, dtype=np.float64) for c in "RGB"], -1)
