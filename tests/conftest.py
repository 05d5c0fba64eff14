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


@pytest.fixture
def effect_package(tmp_path, monkeypatch):
    """Install a module of effects the way pip would: ``install(module, source, {name: class})``
    writes the module and a dist-info with ``mtwin.effects`` entry points on sys.path; the
    registry forgets it afterwards."""
    import sys

    from mtwin import effects as FX

    installed = []

    def install(module: str, source: str, entries: dict) -> None:
        site = tmp_path / "site"
        dist = site / f"{module}-1.0.dist-info"
        dist.mkdir(parents=True)
        (site / f"{module}.py").write_text(source)
        (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module.replace('_', '-')}\nVersion: 1.0\n")
        (dist / "entry_points.txt").write_text(
            "[mtwin.effects]\n" + "".join(f"{n} = {module}:{c}\n" for n, c in entries.items()))
        monkeypatch.syspath_prepend(str(site))
        monkeypatch.setattr(FX, "_entry_points_loaded", None)
        installed.append(module)

    yield install
    FX._entry_points_loaded = None
    for m in installed:
        sys.modules.pop(m, None)
