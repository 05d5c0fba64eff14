"""Proving a rewritten program: the same path (``verify``), or the same part (``verify --by-stock``)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

from ..errors import MtwinError
from ..twin.setup import Messages, load_part, open_twin


MAX_TOL = 1.0  # mm: two paths "the same within" more than this are not the same


@dataclass
class PathProof:
    """``verify``'s answer: the same path within ``tol`` (``difference`` None), or the first
    difference; the two programs as read."""

    original: object
    optimised: object
    tol: float
    difference: object = None

    @property
    def same(self) -> bool:
        return self.difference is None

    def as_dict(self) -> dict:
        return {"same_path": self.same, "tolerance": self.tol,
                **({"difference": self.difference.as_dict()} if self.difference is not None else {})}


def prove_path(twin=None, original=None, optimised=None, *, tol: float = 1e-3,
               on_message: Optional[Callable[[str, str], None]] = None) -> PathProof:
    """Do two programs cut the same path within ``tol`` mm, F and S words and move splits aside
    (:func:`mtwin.gcode.verify.compare`)?  Both are read with the one twin's interpreter."""
    from ..gcode.verify import compare

    _check_tol(tol)
    tw = open_twin(twin)
    msgs = Messages(on_message)
    a = load_part(tw, original, msgs)
    b = load_part(tw, optimised, msgs)
    return PathProof(a, b, tol, compare(a, b, tol))


def _check_tol(tol: float) -> None:
    if not (0 < tol <= MAX_TOL):  # (two paths 1e99 mm apart are not "the same within" anything)
        raise MtwinError(f"--tol must be a positive distance of at most {MAX_TOL:g} mm, got {tol:g}")


def prove_stock(twin=None, original=None, optimised=None, *, stock=None, tol: float = 1e-3,
                on_message: Optional[Callable[[str, str], None]] = None):
    """Run both programs on the original's stock and compare the Z-maps they leave
    (:func:`mtwin.cutting.stockproof.prove_same_stock`).

    ``stock``: the box (xmin, ymin, zmin, xmax, ymax, zmax), mm, over the original's comment,
    the twin file's and the guess; the optimised program runs on the same box whatever its own
    comments say.  Returns a :class:`~mtwin.cutting.stockproof.StockProof`."""
    from ..cutting.stockproof import prove_same_stock
    from ..motion.simulate import program_engagement

    _check_tol(tol)
    tw = open_twin(twin)
    msgs = Messages(on_message)
    a = load_part(tw, original, msgs)
    b = load_part(tw, optimised, msgs)
    plan_a, eng_a = program_engagement(tw, a, stock)
    plan_b, eng_b = program_engagement(tw, b, eng_a.stock.box)  # (the original's stock, whatever b says)
    return prove_same_stock(eng_a, plan_a, eng_b, plan_b, tol)
