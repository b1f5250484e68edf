"""Image helpers for every layer that shows, compares or stores the simulator's images (linear float RGB,
(height, width, 3)): the sRGB display curve and PNG / EXR encoding. numpy, Pillow and OpenEXR only."""

from __future__ import annotations

import io

import numpy as np
import OpenEXR
from PIL import Image


def linear_to_srgb(image: np.ndarray) -> np.ndarray:
    """Clamp linear RGB to [0, 1] (NaN counts as 0) and apply the sRGB transfer curve; float64 out."""
    x = np.clip(np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def encode_png(image: np.ndarray) -> bytes:
    """Linear float RGB -> 8-bit sRGB PNG bytes."""
    buf = io.BytesIO()
    Image.fromarray((linear_to_srgb(image) * 255.0 + 0.5).astype(np.uint8), "RGB").save(buf, format="PNG")
    return buf.getvalue()


def encode_exr(image: np.ndarray) -> bytes:
    """Linear float RGB -> 32-bit float, ZIP-compressed scanline EXR bytes (written in memory)."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    buf = io.BytesIO()
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(image, dtype=np.float32)}) as f:
        f.write(buf)
    return buf.getvalue()
