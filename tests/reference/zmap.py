"""Material removal on a Z-map, cell by cell: a flat end mill swept along straight lines at
constant height lowers every cell its disc covers to its tip.  The volume a move removes is the
sum of what it lowered — the integral of the material removal rate the engagement model reports
(MRR = feed speed x the engaged edge's area normal to the motion) over the move."""
from __future__ import annotations

import math

import numpy as np


class ZMap:
    def __init__(self, box, cell: float):
        x0, y0, _, x1, y1, top = box
        self.x0, self.y0, self.cell = x0, y0, cell
        nx, ny = int(math.ceil((x1 - x0) / cell)), int(math.ceil((y1 - y0) / cell))
        self.h = np.full((ny, nx), float(top))
        self.cx = x0 + (np.arange(nx) + 0.5) * cell
        self.cy = y0 + (np.arange(ny) + 0.5) * cell

    def sweep(self, p0, p1, z: float, radius: float) -> float:
        """Sweep the tool from p0 to p1 (x, y) at height z; returns the volume removed (mm³)."""
        before = self.h.copy()
        n = max(2, int(math.ceil(math.dist(p0, p1) / (0.25 * self.cell))) + 1)
        for u in np.linspace(0.0, 1.0, n):
            px, py = p0[0] + u * (p1[0] - p0[0]), p0[1] + u * (p1[1] - p0[1])
            i0, i1 = np.searchsorted(self.cy, [py - radius, py + radius])
            j0, j1 = np.searchsorted(self.cx, [px - radius, px + radius])
            yy, xx = np.meshgrid(self.cy[i0:i1] - py, self.cx[j0:j1] - px, indexing="ij")
            inside = xx * xx + yy * yy <= radius * radius
            win = self.h[i0:i1, j0:j1]
            win[inside] = np.minimum(win[inside], z)
        return float((before - self.h).sum() * self.cell * self.cell)
