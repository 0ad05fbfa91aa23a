"""Visualisation: the current envelope of an episode drawn into an RGB array (numpy only, no GUI)."""

from __future__ import annotations

import numpy as np

__all__ = ["draw_envelope"]

_COLOURS = {"i2": (31, 119, 180), "rated": (214, 39, 40), "il": (44, 160, 44), "cmd": (0, 0, 0),
            "d": (255, 127, 14)}


def _polyline(img, x_px, y_px, colour, thick=1):
    h, w, _ = img.shape
    if len(x_px) == 0:
        return
    if len(x_px) == 1:
        xs, ys = np.asarray(x_px, float), np.asarray(y_px, float)
    else:
        s = np.linspace(0, len(x_px) - 1, 4 * w)
        xs = np.interp(s, np.arange(len(x_px)), x_px)
        ys = np.interp(s, np.arange(len(y_px)), y_px)
    xi = np.clip(np.round(xs).astype(int), 0, w - 1)
    yi = np.round(ys).astype(int)
    lo = np.minimum(yi, np.r_[yi[1:], yi[-1]])
    hi = np.maximum(yi, np.r_[yi[1:], yi[-1]])
    for x, a, b in zip(xi, lo, hi):   # connect consecutive samples with vertical spans
        img[max(a - thick // 2, 0):min(b + thick - thick // 2, h), x] = colour


def draw_envelope(t_s, i2_a, il_a, cmd_a, d_short, rated_i2_a: float, t_end_s: float,
                  width: int = 600, height: int = 400) -> np.ndarray:
    """RGB image (height, width, 3) uint8: I2 envelope (blue), rated I2 (red), SBAR output current
    I_L (green), charge command (black) on 0..max(60 A, peak) and d_short (orange, 0..1 in the
    bottom band). Time runs left to right over the whole episode window ``t_end_s``."""
    img = np.full((height, width, 3), 255, dtype=np.uint8)
    top, bottom, left, right = 10, height - 70, 10, width - 10
    img[bottom, left:right] = 160
    img[top:bottom, left] = 160
    t = np.asarray(t_s, float)
    x = left + t / t_end_s * (right - left)
    ymax = max(60.0, float(np.max(i2_a)) * 1.05 if len(i2_a) else 60.0)

    def y(v):
        return bottom - np.asarray(v, float) / ymax * (bottom - top)

    img[int(round(float(y(rated_i2_a)))), left:right:3] = _COLOURS["rated"]
    _polyline(img, x, y(cmd_a), _COLOURS["cmd"])
    _polyline(img, x, y(il_a), _COLOURS["il"], 2)
    _polyline(img, x, y(i2_a), _COLOURS["i2"], 2)
    band_top, band_bottom = height - 60, height - 10
    img[band_bottom, left:right] = 160
    _polyline(img, x, band_bottom - np.asarray(d_short, float) * (band_bottom - band_top), _COLOURS["d"], 2)
    return img
