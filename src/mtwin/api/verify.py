"""Proving a rewritten program: the same path (``verify``), or the same part (``verify --by-stock``)."""
from __future__ import annotations

from typing import Callable, Optional

from ..twin.setup import Messages, load_part, open_twin


def prove_stock(twin=None, original=None, optimised=None, *, stock=None, tol: float = 1e-3,
                on_message: Optional[Callable[[str, str], None]] = None):
    """Run both programs on the original's stock and compare the Z-maps they leave
    (:func:`mtwin.cutting.stockproof.prove_same_stock`).

    ``stock``: the box (xmin, ymin, zmin, xmax, ymax, zmax), mm, over the original's comment,
    the twin file's and the guess; the optimised program runs on the same box whatever its own
    comments say.  Returns a :class:`~mtwin.cutting.stockproof.StockProof`."""
    from ..cutting.stockproof import prove_same_stock
    from ..errors import MtwinError
    from ..motion.simulate import program_engagement

    if not (0 < tol <= 1.0):
        raise MtwinError(f"the stock tolerance must be a positive distance of at most 1 mm, got {tol:g}")
    tw = open_twin(twin)
    msgs = Messages(on_message)
    a = load_part(tw, original, msgs)
    b = load_part(tw, optimised, msgs)
    plan_a, eng_a = program_engagement(tw, a, stock)
    plan_b, eng_b = program_engagement(tw, b, eng_a.stock.box)  # (the original's stock, whatever b says)
    return prove_same_stock(eng_a, plan_a, eng_b, plan_b, tol)
