import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# the CLI runs the tests start must not leave compiles running in the background
os.environ.setdefault("MTWIN_BACKGROUND_COMPILE", "0")
SHARED = Path(os.environ.get("MTWIN_SHARED", ROOT.parent / "shared"))
REALDATA = SHARED / "realdata"
SAMPLES = ROOT / "samples"


def realdata_files():
    """Every G-code file of ../shared/realdata (empty if it is absent)."""
    if not REALDATA.is_dir():
        return []
    exts = (".nc", ".ngc", ".tap", ".gcode")
    return sorted(p for p in REALDATA.rglob("*") if p.is_file() and p.suffix.lower() in exts)


def require_realdata():
    if not REALDATA.is_dir():
        pytest.skip(f"{REALDATA} not present")
