"""Proof by the part: two programs leave the same stock.

``verify`` proves that a feed and speed rewrite cuts the same path.  A program that cuts a
segment in layers cuts another path to the same part, so its proof is the part itself: both
programs run on one stock (the original's box, guessed, read or given, so both start from the
same material) and the Z-maps they leave are compared cell by cell.  The proof holds when

* every cell's height is the same within the tolerance, or is a height the other map has
  within one cell around (the proof is "within the cell size": a cell at the very edge of a
  tool's sweep is cut or not as the path's steps happen to fall),
* no cell is cut deeper than that (the final depth is never exceeded), and
* no rapid of the rewritten program goes through material standing at that moment (the
  engagement kernel checks each rapid against the stock as it is then) where the original's
  rapids do not.

A failed proof names the cell with the largest difference, its heights, and the feed moves of
each program nearest to it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..layout import PAUSE


@dataclass
class StockProof:
    """The result of :func:`prove_same_stock`."""

    tolerance: float  # mm, in Z
    resolution: float  # mm, the Z-map's cell size
    box: tuple  # the stock both programs ran on
    cells: int  # cells compared
    max_difference: float  # mm, the largest |optimised − original| height
    deeper: float  # mm, how far the optimised program cut below the original anywhere (0: nowhere)
    worst: dict | None  # the cell with the largest difference: x, y, heights, nearest lines
    rapid_line: int  # a line of the optimised program whose rapid goes through stock, else 0
    original: np.ndarray  # (ny, nx) heights the original leaves
    optimised: np.ndarray  # (ny, nx) heights the optimised program leaves

    @property
    def same(self) -> bool:
        return self.max_difference <= self.tolerance and self.rapid_line == 0

    def reason(self) -> str:
        """What the proof found, in a sentence."""
        if self.rapid_line:
            return f"line {self.rapid_line} of the optimised program rapids through stock"
        if self.same:
            return (f"same stock: {self.cells:,} cells of {self.resolution:g} mm within {self.tolerance:g} mm "
                    f"(largest difference {self.max_difference:.2g} mm)")
        w = self.worst
        how = "deeper than" if w["optimised_z"] < w["original_z"] else "short of"
        return (f"stock differs at X{w['x']:.3f} Y{w['y']:.3f}: the optimised program leaves Z{w['optimised_z']:.3f}, "
                f"{abs(w['optimised_z'] - w['original_z']):.3f} mm {how} the original's Z{w['original_z']:.3f} "
                f"(nearest feed moves: original line {w['original_line']}, optimised line {w['optimised_line']})")

    def as_dict(self) -> dict:
        return {"same_stock": self.same, "tolerance": self.tolerance, "resolution": self.resolution,
                "box": list(self.box), "cells": self.cells, "max_difference": self.max_difference,
                "deeper": self.deeper, "worst": self.worst, "rapid_through_stock_line": self.rapid_line or None}


def prove_same_stock(eng_a, plan_a, eng_b, plan_b, tol: float = 1e-3) -> StockProof:
    """Compare the stock two engagements leave (``eng_b`` run on ``eng_a``'s box)."""
    ha, hb = eng_a.stock.heights, eng_b.stock.heights
    if ha.shape != hb.shape or tuple(eng_a.stock.box) != tuple(eng_b.stock.box):
        raise ValueError("the two programs were not run on the same stock")
    d = _beyond_one_cell(ha.astype(np.float64), hb.astype(np.float64), tol)
    worst = None
    max_diff = float(np.abs(d).max()) if d.size else 0.0
    if max_diff > tol:
        iy, ix = np.unravel_index(int(np.argmax(np.abs(d))), d.shape)
        res = eng_a.stock.resolution
        x = eng_a.stock.box[0] + (ix + 0.5) * res
        y = eng_a.stock.box[1] + (iy + 0.5) * res
        za, zb = float(ha[iy, ix]), float(hb[iy, ix])
        worst = {"x": x, "y": y, "original_z": za, "optimised_z": zb,
                 "original_line": _nearest_line(plan_a, x, y, min(za, zb)),
                 "optimised_line": _nearest_line(plan_b, x, y, min(za, zb))}
    rapid = _added_rapid(eng_a, plan_a, eng_b, plan_b)
    return StockProof(tol, float(eng_a.stock.resolution), tuple(eng_a.stock.box), int(d.size), max_diff,
                      float(max(0.0, -d.min())) if d.size else 0.0, worst, rapid, ha, hb)


def _added_rapid(eng_a, plan_a, eng_b, plan_b) -> int:
    """The line of the first rapid of the rewritten program that goes through stock where no
    rapid of the original does (0: none).  A rapid through stock the original has too — the same
    move, end to end — is the program's own (a guessed stock, often), not one the rewriting
    added; any other is, however many the original has (a link of a layered cut)."""
    def moves(eng, plan):
        return [(tuple(np.round(plan.seg["p0"][i], 4)), tuple(np.round(plan.seg["p1"][i], 4)), int(plan.seg["line"][i]))
                for i in eng.rapid_segments]

    own = {(a, b) for a, b, _ in moves(eng_a, plan_a)}
    added = [line for a, b, line in moves(eng_b, plan_b) if (a, b) not in own]
    return added[0] if added else 0


def _beyond_one_cell(ha: np.ndarray, hb: np.ndarray, tol: float) -> np.ndarray:
    """hb − ha where it is not explained by a shift of one cell: a cell at the very edge of a
    tool's sweep is cut or not as the path's steps fall (the same arc split in two, 0.004 mm
    inside the radius, left a 5.5-mm step in one map and not the other), so a height that the
    other map has within one cell around counts as the same (the proof is "within the cell
    size"); the rest keeps its difference."""
    from scipy.ndimage import maximum_filter, minimum_filter

    d = hb - ha
    bad = np.abs(d) > tol
    if not bad.any():
        return d
    lo_a, hi_a = minimum_filter(ha, 3, mode="nearest"), maximum_filter(ha, 3, mode="nearest")
    lo_b, hi_b = minimum_filter(hb, 3, mode="nearest"), maximum_filter(hb, 3, mode="nearest")
    near = (hb >= lo_a - tol) & (hb <= hi_a + tol) & (ha >= lo_b - tol) & (ha <= hi_b + tol)
    return np.where(bad & near, 0.0, d)


def _nearest_line(plan, x: float, y: float, z: float) -> int:
    """The line of the feed move nearest to (x, y) in the plane among those that reach down to
    ``z`` (+ 1 mm), 0 when there is none."""
    seg = plan.tip_seg
    feed = (seg["kind"] != PAUSE) & (seg["rapid"] == 0)
    p0, p1 = seg["p0"], seg["p1"]
    low = np.minimum(p0[:, 2], p1[:, 2]) <= z + 1.0
    pick = np.flatnonzero(feed & low) if (feed & low).any() else np.flatnonzero(feed)
    if not len(pick):
        return 0
    a, b = p0[pick, :2], p1[pick, :2]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", np.array([x, y]) - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300),
                0.0, 1.0)
    dist = np.hypot(*(a + t[:, None] * ab - np.array([x, y])).T)
    return int(seg["line"][pick[int(np.argmin(dist))]])
