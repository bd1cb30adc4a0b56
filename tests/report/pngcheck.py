"""Decode PNGs (matplotlib.image) and find images in a page screenshot, for the report tests."""
from __future__ import annotations

import base64
import io
import re

import numpy as np

#: an <img> of a report: base64 PNG and its declared size
IMG_RE = re.compile(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)" width="(\d+)" height="(\d+)"')


def decode_png(data: bytes) -> np.ndarray:
    """RGB uint8 array (h, w, 3) of a PNG (alpha composited on white)."""
    import matplotlib.image as mpimg

    a = mpimg.imread(io.BytesIO(data), format="png")
    if a.dtype != np.uint8:
        a = np.round(np.clip(a, 0, 1) * 255).astype(np.uint8)
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    if a.shape[2] == 4:
        alpha = a[:, :, 3:4].astype(float) / 255
        a = np.round(a[:, :, :3] * alpha + 255 * (1 - alpha)).astype(np.uint8)
    return a


def embedded_images(html: str) -> list[tuple[bytes, int, int]]:
    """``(png bytes, declared width, declared height)`` of every embedded image, in page order."""
    return [(base64.b64decode(m.group(1)), int(m.group(2)), int(m.group(3))) for m in IMG_RE.finditer(html)]


def ink_stats(rgb: np.ndarray, white_tol: int = 12) -> tuple[float, int]:
    """Share of pixels that are not (near) white, and number of distinct colours among them."""
    px = rgb.reshape(-1, 3).astype(int)
    ink = np.any(px < 255 - white_tol, axis=1)
    colours = np.unique(px[ink], axis=0).shape[0] if ink.any() else 0
    return float(ink.mean()), int(colours)


def saturated_share(rgb: np.ndarray, min_chroma: int = 60) -> float:
    """Share of pixels with a clear colour (max - min channel >= min_chroma): curves, not text."""
    px = rgb.reshape(-1, 3).astype(int)
    return float(np.mean(px.max(axis=1) - px.min(axis=1) >= min_chroma))


def find_image(shot: np.ndarray, img: np.ndarray, tol: float = 3.0) -> tuple[int, int] | None:
    """Top-left ``(y, x)`` where ``img`` appears 1:1 in ``shot`` (mean absolute difference per channel
    below ``tol``), or None.

    The most varied row of the image is searched for in every row of the screenshot (exact bytes
    first; then within ``tol``, aligning the first non-white pixels); candidates are confirmed on
    the whole image.
    """
    h, w, _ = img.shape
    H, Wd, _ = shot.shape
    if h > H or w > Wd:
        return None
    variety = np.count_nonzero(np.any(np.diff(img.astype(int), axis=1) != 0, axis=2), axis=1)
    r0 = int(np.argmax(variety))
    needle = img[r0].tobytes()

    def confirm(y, x):
        if y < 0 or y + h > H or x < 0 or x + w > Wd:
            return False
        patch = shot[y:y + h, x:x + w].astype(int)
        return float(np.mean(np.abs(patch - img.astype(int)))) < tol

    for yy in range(r0, H - (h - r0) + 1):
        row = shot[yy].tobytes()
        start = 0
        while True:
            k = row.find(needle, start)
            if k < 0:
                break
            if k % 3 == 0 and confirm(yy - r0, k // 3):
                return yy - r0, k // 3
            start = k + 1
    # not byte-identical (colour management): align the first non-white pixel of the row, then compare
    target = img[r0].astype(int)
    ink = np.flatnonzero(np.any(target < 243, axis=1))
    if ink.size == 0:
        return None
    for yy in range(r0, H - (h - r0) + 1):
        row_ink = np.flatnonzero(np.any(shot[yy].astype(int) < 243, axis=1))
        if row_ink.size == 0:
            continue
        x = int(row_ink[0] - ink[0])
        if 0 <= x <= Wd - w and np.mean(np.abs(shot[yy, x:x + w].astype(int) - target)) < tol and confirm(yy - r0, x):
            return yy - r0, x
    return None
