"""The stock after the last cut, for a person to look at: a height-map image or an STL."""
from __future__ import annotations

import io
import struct

import numpy as np

from ..errors import MtwinError

MAX_STL_CELLS = 400 * 400  # the STL is decimated to at most this many cells (2 triangles each)


def stock_bytes(stock, path: str) -> bytes:
    if path.endswith(".png"):
        return _png(stock)
    if path.endswith(".stl"):
        return _stl(stock)
    raise MtwinError(f"--stock-out {path}: use a .png (height map) or .stl (surface) file name")


def _png(stock) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    b = stock.box
    fig, ax = plt.subplots(figsize=(7, 7 * (b[4] - b[1]) / max(b[3] - b[0], 1e-9) + 0.6), dpi=120)
    im = ax.imshow(stock.heights, origin="lower", extent=(b[0], b[3], b[1], b[4]), cmap="viridis",
                   vmin=b[2], vmax=b[5], interpolation="nearest")
    fig.colorbar(im, ax=ax, label="height [mm]", shrink=0.8)
    ax.set_xlabel("X [mm]")
    ax.set_ylabel("Y [mm]")
    ax.set_title(f"stock after the program ({stock.resolution:g} mm cells)", fontsize=9)
    buf = io.BytesIO()
    from .plots import save_figure

    save_figure(fig, buf, "png", bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def _stl(stock) -> bytes:
    H = stock.heights
    ny, nx = H.shape
    k = max(1, int(np.ceil(np.sqrt(nx * ny / MAX_STL_CELLS))))
    Z = H[::k, ::k].astype(np.float32)
    my, mx = Z.shape
    b = stock.box
    xs = b[0] + (np.arange(mx) * k + 0.5) * stock.resolution
    ys = b[1] + (np.arange(my) * k + 0.5) * stock.resolution
    X, Y = np.meshgrid(xs, ys)
    P = np.stack([X, Y, Z], axis=-1).astype(np.float32)
    a, bb, c, d = P[:-1, :-1], P[:-1, 1:], P[1:, 1:], P[1:, :-1]
    tris = np.concatenate([np.stack([a, bb, c], axis=-2).reshape(-1, 3, 3),
                           np.stack([a, c, d], axis=-2).reshape(-1, 3, 3)])
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    rec = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"] = n
    rec["v"] = tris
    header = b"mtwin stock height field".ljust(80, b" ")
    return header + struct.pack("<I", len(tris)) + rec.tobytes()
