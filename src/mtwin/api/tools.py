"""The tool ledger as use cases: ``mtwin tools`` (every tool) and ``mtwin tools show`` (one)."""
from __future__ import annotations

from ..errors import MtwinError
from ..ledger import VB_LIMIT, Ledger

__all__ = ["MAX_VB_LIMIT", "VB_LIMIT", "check_vb_limit", "tool", "tools"]

MAX_VB_LIMIT = 10.0  # mm: ISO 8688-2 ends an end mill's life at a 0.3-mm land; 10 mm is no flank land


def check_vb_limit(vb_limit: float) -> None:
    if not 0 < vb_limit <= MAX_VB_LIMIT:
        raise MtwinError(f"--vb-limit must be a flank-wear land in mm from 0 to {MAX_VB_LIMIT:g}, got {vb_limit:g}")


def tools(ledger: str, *, vb_limit: float = VB_LIMIT) -> dict:
    """Every tool of a ledger: its runs, path cut, sliding, time, the land now and the parts left
    to ``vb_limit`` (mm), as ``mtwin tools --json`` prints it."""
    check_vb_limit(vb_limit)
    with Ledger(ledger, create=False) as lg:
        found = [lg.tool(i) for i in lg.ids()]
    rows = [{"id": t.id, "runs": t.runs, "length_mm": round(t.history.length, 3),
             "sliding_m": round(t.history.sliding, 4), "time_s": round(t.history.time, 3),
             "calibrated": t.law is not None, **t.wear(vb_limit)} for t in found]
    return {"ledger": ledger, "tools": rows}


def tool(ledger: str, ident: str, *, vb_limit: float = VB_LIMIT) -> dict:
    """One tool of a ledger: its law, wear, history, runs and calibrations (``tools show --json``)."""
    check_vb_limit(vb_limit)
    with Ledger(ledger, create=False) as lg:
        t = lg.tool(ident)
        runs, cals = lg.runs(ident), lg.calibrations(ident)
    return {"id": t.id, "created": t.created, "law": t.law, "wear": t.wear(vb_limit),
            "history": t.history.__dict__, "runs": runs, "calibrations": cals}
