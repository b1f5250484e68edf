"""Image helpers, once for the tracer, the evaluator, the service's previews and the scene generators:
bilinear resize, the sRGB transfer curves, OpenEXR files and PNG / EXR encoding.

Images are (H, W, 3) float linear RGB, row 0 at the top. Low in the package (numpy, OpenEXR, Pillow
only) so that everything above it, ``service`` included, can use it.
"""

from __future__ import annotations

import io
import os
from typing import BinaryIO

import numpy as np
import OpenEXR
from PIL import Image

from .scene_data import finite_clamped


def upsample_bilinear(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """Bilinear resize of an (h, w[, c]) image to (height, width) with pixel centres aligned (what a
    display upscaler does). float32 in gives float32 out (the tracer's images); anything else float64."""
    img = np.asarray(image)
    dtype = np.float32 if img.dtype == np.float32 else np.float64
    img = img.astype(dtype, copy=False)
    h, w = img.shape[:2]
    if (h, w) == (height, width):
        return img
    ys = np.clip((np.arange(height) + 0.5) * h / height - 0.5, 0, h - 1)
    xs = np.clip((np.arange(width) + 0.5) * w / width - 0.5, 0, w - 1)
    y0, x0 = np.floor(ys).astype(np.int64), np.floor(xs).astype(np.int64)
    y1, x1 = np.minimum(y0 + 1, h - 1), np.minimum(x0 + 1, w - 1)
    extra = (None,) * (img.ndim - 2)
    fy = (ys - y0).astype(dtype)[(slice(None), None, *extra)]
    fx = (xs - x0).astype(dtype)[(None, slice(None), *extra)]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bot = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return (top * (1 - fy) + bot * fy).astype(dtype, copy=False)


def linear_to_srgb(image: np.ndarray) -> np.ndarray:
    """The display transform: linear values clamped to [0, 1] (NaN as 0, +Inf as 1), then the sRGB OETF;
    float64 out."""
    x = np.nan_to_num(np.asarray(image, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_linear(values: np.ndarray) -> np.ndarray:
    """The sRGB EOTF (encoded colour in [0, 1] -> linear light), e.g. for texture colours."""
    c = np.asarray(values, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def load_exr(path: str | os.PathLike[str]) -> np.ndarray:
    """Read an OpenEXR image as (H, W, 3) float32 linear RGB (e.g. an equirectangular environment map).

    Raises FileNotFoundError when the file is missing and ValueError when it is not a readable RGB EXR.
    Negative and non-finite texels (most of Blender's bundled HDRIs hold tiny negative ones) are clamped
    with a warning, never rejected.
    """
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise FileNotFoundError(f"EXR file not found: {p}")
    try:
        with OpenEXR.File(p) as f:
            channels = f.channels()
            if "RGB" in channels:
                rgb = np.asarray(channels["RGB"].pixels, dtype=np.float32)
            elif "RGBA" in channels:
                rgb = np.asarray(channels["RGBA"].pixels, dtype=np.float32)[..., :3]
            elif all(c in channels for c in "RGB"):
                rgb = np.stack([np.asarray(channels[c].pixels, dtype=np.float32) for c in "RGB"], axis=-1)
            else:
                raise ValueError(f"{p}: EXR has no R, G, B channels ({sorted(channels)})")
    except ValueError:
        raise
    except Exception as exc:
        raise ValueError(f"{p}: not a readable EXR file ({exc})") from None
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"{p}: expected an (H, W, 3) image, got shape {rgb.shape}")
    return np.ascontiguousarray(finite_clamped(rgb, p))


def write_exr(target: str | os.PathLike[str] | BinaryIO, image: np.ndarray) -> None:
    """(H, W, 3) linear RGB as a ZIP-compressed 32-bit float scanline OpenEXR, to a file or a binary
    stream (half floats would lose a sun's range)."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(image, dtype=np.float32)}) as f:
        f.write(target if isinstance(target, io.IOBase) else os.fspath(target))


def encode_exr(image: np.ndarray) -> bytes:
    """:func:`write_exr`'s bytes, written in memory."""
    buf = io.BytesIO()
    write_exr(buf, image)
    return buf.getvalue()


def encode_png(image: np.ndarray) -> bytes:
    """Linear float RGB -> 8-bit sRGB PNG (NaN shows black, +Inf white)."""
    buf = io.BytesIO()
    Image.fromarray((linear_to_srgb(image) * 255.0 + 0.5).astype(np.uint8), "RGB").save(buf, format="PNG")
    return buf.getvalue()
