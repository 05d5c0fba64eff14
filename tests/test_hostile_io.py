"""Nothing a user names is destroyed, no reader follows a device (issue 33, items 1 and 2):
each reproduction of the hostile trial that concerned input and output paths."""
from __future__ import annotations

import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

PROG = b"(T1 D=6 CR=0 - flat end mill)\nG21 G90 G17\nT1 M6\nS8000 M3\nG0 X-5 Y0 Z5\nG0 Z-1\nG1 X30 F300\nG0 Z5\nM30\n"


def run(*args, env=None, timeout=120):
    e = dict(os.environ, **(env or {}))
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-m", "mtwin", *map(str, args)], capture_output=True, timeout=timeout, env=e)
    return p.returncode, p.stderr.decode(), time.monotonic() - t0


@pytest.fixture
def files(tmp_path):
    prog = tmp_path / "p.nc"
    prog.write_bytes(PROG)
    twin = tmp_path / "t.toml"
    twin.write_text('[cutting]\nmaterial = "6061"\n')
    return tmp_path, prog, twin


def _snapshot(folder: Path) -> dict:
    return {p.name: (p.lstat().st_mode, p.read_bytes() if p.is_file() and not p.is_symlink() else os.readlink(p)
                     if p.is_symlink() else None) for p in folder.iterdir()}


@pytest.mark.parametrize("case", ["simulate-program", "simulate-twin", "optimize-twin", "synth-program",
                                  "compare-measurement"])
def test_no_output_replaces_an_input(files, case):
    d, prog, twin = files
    meas = d / "m.csv"
    meas.write_text("t,spindle_power\n0,100\n0.1,100\n")
    args = {"simulate-program": ["simulate", prog, "-o", prog],
            "simulate-twin": ["simulate", prog, "--twin", twin, "-o", twin],
            "optimize-twin": ["optimize", prog, "--twin", twin, "-o", twin],
            "synth-program": ["synth", prog, "-o", prog],
            "compare-measurement": ["compare", prog, meas, "--report", d / "r.html", "--twin", twin]}[case]
    before = _snapshot(d)
    code, err, _ = run(*args)
    if case == "compare-measurement":  # (an output beside the inputs: fine, nothing of theirs changes)
        assert {k: v for k, v in _snapshot(d).items() if k != "r.html"} == before
        return
    assert code == 2 and "refusing to overwrite" in err and "Traceback" not in err, err
    assert _snapshot(d) == before


def test_a_symlink_output_is_refused_and_the_link_kept(files):
    d, prog, twin = files
    link = d / "out.nc"
    link.symlink_to(twin)
    before = _snapshot(d)
    code, err, _ = run("optimize", prog, "-o", link)
    assert code == 2 and "symbolic link" in err
    assert _snapshot(d) == before


def test_a_device_output_is_written_through_not_replaced(files):
    d, prog, _ = files
    code, err, _ = run("optimize", prog, "-o", "/dev/null")
    assert code == 0, err
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


@pytest.mark.parametrize("kind", ["program", "twin", "measurement", "frf"])
def test_no_reader_follows_a_device_or_a_fifo(files, kind):
    d, prog, twin = files
    fifo = d / "fifo"
    os.mkfifo(fifo)
    for src in ("/dev/zero", fifo):
        if kind == "program":
            args = ["parse", src]
        elif kind == "twin":
            args = ["simulate", prog, "--twin", src]
        elif kind == "measurement":
            args = ["compare", prog, src]
        else:
            t = d / "frf.toml"
            t.write_text(f'[tools.1]\ntype = "flat"\ndiameter = 6.0\nflutes = 2\nfrf = "{src}"\n')
            args = ["lobes", "--twin", t, "--tool", "1"]
        # (a path outside the twin file's folder needs the user's leave: given, the device is refused)
        code, err, secs = run(*args, timeout=60, env={"MTWIN_TRUST_TWIN_PATHS": "1"} if kind == "frf" else None)
        assert code == 2 and ("a device" in err or "a FIFO" in err) and "Traceback" not in err, (src, err)
        assert secs < 30


def test_a_size_limit_per_kind(files):
    d, prog, _ = files
    code, err, _ = run("parse", prog, env={"MTWIN_MAX_PROGRAM_MB": "0.00001"})
    assert code == 2 and "MTWIN_MAX_PROGRAM_MB" in err
    code, err, _ = run("parse", prog, env={"MTWIN_MAX_PROGRAM_MB": "1"})
    assert code == 0, err


def test_a_twin_files_frf_outside_its_folder_needs_the_users_leave(tmp_path):
    (tmp_path / "secret").mkdir()
    secret = tmp_path / "secret" / "secret.env"
    secret.write_text("API_KEY=hunter2\n")
    d = tmp_path / "twins"
    d.mkdir()
    for ref in ("../secret/secret.env", str(secret)):
        t = d / "t.toml"
        t.write_text(f'[tools.1]\ntype = "flat"\ndiameter = 6.0\nflutes = 2\nfrf = "{ref}"\n')
        code, err, _ = run("lobes", "--twin", t, "--tool", "1")
        assert code == 2 and "outside the twin file's folder" in err and "MTWIN_TRUST_TWIN_PATHS" in err, err
        assert "hunter2" not in err
        code, err, _ = run("lobes", "--twin", t, "--tool", "1", env={"MTWIN_TRUST_TWIN_PATHS": "1"})
        assert code == 2 and "outside the twin file's folder" not in err  # (read, and refused as no FRF)
        assert "hunter2" not in err, err
