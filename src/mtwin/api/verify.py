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
    from ..cutting.engagement import engagement_for
    from ..cutting.stockproof import prove_same_stock
    from ..errors import MtwinError
    from ..motion.simulate import _program_cutting

    if not (tol > 0):
        raise MtwinError("the stock tolerance must be positive")
    tw = open_twin(twin)
    msgs = Messages(on_message)
    a = load_part(tw, original, msgs)
    b = load_part(tw, optimised, msgs)
    plan_a, plan_b = tw.plan(a), tw.plan(b)
    eng_a = engagement_for(plan_a, a, _program_cutting(tw, a), stock, cache=tw.engagement_cache)
    eng_b = engagement_for(plan_b, b, _program_cutting(tw, b), eng_a.stock.box, cache=tw.engagement_cache)
    return prove_same_stock(eng_a, plan_a, eng_b, plan_b, tol)
