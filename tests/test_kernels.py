"""The kernels: their plain-Python originals give the compiled results, and the compile cache
warms up in the background on a first run (moved from test_first_hour.py; the kernels against
independent slow references are in test_reference.py)."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from conftest import SAMPLES, realdata_files


def _programs():
    progs = sorted(SAMPLES.glob("*.nc"))
    real = [p for p in realdata_files() if "/bad/" not in str(p)]
    return progs + real[::4]  # every fourth real program keeps this under a minute


def test_kernels_run_as_plain_python_give_the_compiled_results():
    # small programs are lexed and interpreted by the kernels' Python originals while the
    # compiled code is not at hand (first run); they must give exactly the compiled records
    from mtwin.errors import GCodeError
    from mtwin.gcode.interpreter import InterpreterSettings, load_program

    def load(p, mode):
        old = os.environ.get("MTWIN_KERNELS")
        os.environ["MTWIN_KERNELS"] = mode
        try:
            return load_program(str(p), InterpreterSettings(lenient=True))
        except GCodeError as exc:
            return str(exc)
        finally:
            if old is None:
                del os.environ["MTWIN_KERNELS"]
            else:
                os.environ["MTWIN_KERNELS"] = old

    checked = 0
    for p in _programs():
        a, b = load(p, "compiled"), load(p, "python")
        if isinstance(a, str) or isinstance(b, str):
            assert a == b, p.name
            continue
        assert a.records.dtype == b.records.dtype and len(a.records) == len(b.records), p.name
        for name in a.records.dtype.names:
            x, y = a.records[name], b.records[name]
            if x.dtype.kind == "f":  # LLVM may fuse a multiply-add where Python rounds twice
                np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-9, err_msg=f"{p.name} {name}")
            else:
                np.testing.assert_array_equal(x, y, err_msg=f"{p.name} {name}")
        assert [str(w) for w in a.warnings] == [str(w) for w in b.warnings], p.name
        checked += 1
    assert checked >= len(list(SAMPLES.glob("*.nc")))


@pytest.mark.parametrize("style", ["fanuc", "linuxcnc", "grbl"])
def test_planner_kernels_as_plain_python_give_the_compiled_plan(style, monkeypatch):
    import mtwin as api

    programs = sorted(SAMPLES.glob("*.nc")) + [SAMPLES.parent / "tests" / "data" / "linuxcnc" / "naive_cam.ngc"]
    for p in programs:
        tw = api.Twin().with_controller(style=style)
        prog = tw.load(str(p))
        monkeypatch.setenv("MTWIN_KERNELS", "compiled")
        a = tw.plan(prog)
        monkeypatch.setenv("MTWIN_KERNELS", "python")
        b = tw.plan(prog)
        assert len(a.seg) == len(b.seg), p.name
        for name in a.seg.dtype.names:
            np.testing.assert_allclose(a.seg[name], b.seg[name], rtol=1e-9, atol=1e-9, err_msg=f"{p.name} {name}")
        np.testing.assert_allclose(a.prof, b.prof, rtol=1e-9, atol=1e-9, err_msg=p.name)
        np.testing.assert_allclose(a.dur, b.dur, rtol=1e-9, atol=1e-12, err_msg=p.name)


def test_the_warm_up_lock_admits_one_process_and_replaces_a_dead_ones(tmp_path, monkeypatch):
    from mtwin import warmup

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    with warmup.background_lock():
        assert warmup.warming()
        with pytest.raises(warmup.AlreadyWarming):
            with warmup.background_lock():
                pass
    assert not warmup.warming()
    (tmp_path / "warming.lock").write_text("999999999")  # a process that is gone
    assert not warmup.warming()
    with warmup.background_lock():
        assert warmup.warming()
    monkeypatch.setenv("MTWIN_BACKGROUND_COMPILE", "0")
    assert warmup.start_background() is False


def test_a_first_run_on_an_empty_cache_compiles_in_the_background(tmp_path):
    # a 5,000-line program: above the interpreter's Python-is-cheaper size, below its
    # compile-is-dearer size: run as Python now, compiled in the background for next time
    import signal
    import subprocess
    import sys
    import time

    sys.path.insert(0, str(SAMPLES.parent / "benchmarks"))
    from bench_parse import generate

    prog = tmp_path / "mid.nc"
    prog.write_bytes(generate(5000))
    cache = tmp_path / "cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), MTWIN_BACKGROUND_COMPILE="1")
    r = subprocess.run([sys.executable, "-m", "mtwin", "parse", str(prog), "--json"], env=env, capture_output=True)
    assert r.returncode == 0, r.stderr.decode()
    assert "in the background for the next runs" in r.stderr.decode()
    assert json.loads(r.stdout)["lines"] >= 4990
    lock = cache / "warming.lock"
    for _ in range(100):
        if lock.exists() and lock.read_text().strip():
            break
        time.sleep(0.1)
    pid = int(lock.read_text())
    os.killpg(os.getpgid(pid), signal.SIGTERM)  # a test does not wait a minute for it
