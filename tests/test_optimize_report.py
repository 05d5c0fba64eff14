"""The optimisation report renders in a real browser: headless Chromium (Debian's ``chromium``,
installed by .ci/run when missing) loads it with no console message and draws the plots."""
from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
from conftest import SAMPLES

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no headless Chromium on this machine (Debian: apt-get "
                                                          "install chromium; .ci/run installs it)")


def _render(page, tmp_path):
    png = tmp_path / "shot.png"
    dom = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr", "--v=0",
                          "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120)
    subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                    "--window-size=1200,2600", f"--screenshot={png}", page.as_uri()], capture_output=True, timeout=120)
    console = [ln for ln in dom.stderr.splitlines() if ":CONSOLE" in ln or "Uncaught" in ln]
    return dom.stdout, console, png


def test_the_console_check_sees_errors(tmp_path):
    page = tmp_path / "bad.html"
    page.write_text("<!DOCTYPE html><html><body><script>undefinedFunction();</script></body></html>")
    _, console, _ = _render(page, tmp_path)
    assert any("undefinedFunction" in c for c in console)


def test_report_renders_without_console_errors_and_draws_its_plots(tmp_path):
    import matplotlib.image as mpimg

    import sys

    r = subprocess.run([sys.executable, "-m", "mtwin", "optimize", str(SAMPLES / "ga_reference.nc"), "-o",
                        str(tmp_path / "o.nc"), "--method", "ga", "--feed-range", "100,500", "--spindle-range",
                        "1000,8000", "--force-limit", "60", "--report", str(tmp_path / "r.html")],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    page = tmp_path / "r.html"
    text = page.read_text()
    import re

    # self-contained: nothing loaded from elsewhere (XML namespace names are not loads)
    assert not re.search(r"""(src|href)\s*=\s*["'](https?:|//)""", text)
    assert "<link" not in text and "@import" not in text
    dom, console, png = _render(page, tmp_path)
    assert console == []
    assert dom.count("<svg") >= 3  # power and load, feed, trade-off
    assert dom.count("<path") > 50
    assert "Changed lines" in dom and "limited by" in dom
    img = mpimg.imread(str(png))[..., :3]
    # the plots are drawn: a good share of the page is neither white nor near-white
    inked = (img.mean(axis=2) < 0.9).mean()
    assert inked > 0.03, inked
    # the curves themselves: blue (power) and red (load) lines are on the page
    blue = ((img[..., 2] > 0.5) & (img[..., 0] < 0.3)).mean()
    red = ((img[..., 0] > 0.55) & (img[..., 1] < 0.35) & (img[..., 2] < 0.35)).mean()
    assert blue > 1e-4 and red > 1e-4, (blue, red)
    assert np.isfinite(inked)

