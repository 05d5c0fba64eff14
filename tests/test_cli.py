"""The real CLI, run as a subprocess: exit codes, streams, atomic output, JSON keys."""
import json
import os
import subprocess
import sys

import pytest

from conftest import SAMPLES

POCKET = str(SAMPLES / "pocket.nc")


def mtwin(*args, stdin=None):
    return subprocess.run([sys.executable, "-m", "mtwin", *args], input=stdin, capture_output=True)


def test_help_does_not_import_numba():
    code = "import sys; sys.argv=['mtwin','--help']\nfrom mtwin.cli import app\ntry:\n    app()\nexcept SystemExit:\n    pass\nprint('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.stdout.strip().endswith("False")


def test_parse_json_keys():
    r = mtwin("parse", POCKET, "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    for key in ("lines", "moves", "tools", "feed_range", "spindle_range", "bbox", "rapid_length",
                "cutting_length", "nominal_time"):
        assert key in d
    assert d["moves"]["arc_ccw"] == 36 and d["tools"] == [1]


def test_parse_moves_csv_header():
    r = mtwin("parse", POCKET, "--moves")
    lines = r.stdout.decode().splitlines()
    assert lines[0] == "line,kind,x,y,z,cx,cy,cz,feed,spindle,tool"
    assert any(",arc_ccw," in l for l in lines)


def test_stdin_to_stdout_pipeline():
    data = (SAMPLES / "contour.nc").read_bytes()
    r = mtwin("scale", "-", "--feed", "1.0", "-o", "-", stdin=data)
    assert r.returncode == 0 and r.stdout == data
    assert b"wrote" in r.stderr


def test_scale_then_verify(tmp_path):
    out = tmp_path / "fast.nc"
    r = mtwin("scale", POCKET, "--feed", "1.2", "-o", str(out))
    assert r.returncode == 0, r.stderr
    r = mtwin("verify", POCKET, str(out), "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["same_path"] is True


def test_verify_reports_first_difference(tmp_path):
    bad = tmp_path / "bad.nc"
    bad.write_bytes(SAMPLES.joinpath("pocket.nc").read_bytes().replace(b"G1 Z-4.0", b"G1 Z-4.1"))
    r = mtwin("verify", POCKET, str(bad), "--json")
    assert r.returncode == 1
    d = json.loads(r.stdout)
    assert d["same_path"] is False and d["difference"]["original_line"] > 0


def test_bad_input_exit_2_message_and_nothing_written(tmp_path):
    bad = tmp_path / "bad.nc"
    bad.write_text("G1 X10 F100\nG2 X20 Y0 I3 J0\n")
    out = tmp_path / "out.nc"
    r = mtwin("scale", str(bad), "--feed", "0.5", "-o", str(out))
    assert r.returncode == 2
    assert f"{bad}:2:1:".encode() in r.stderr and b"Traceback" not in r.stderr
    assert not out.exists() and os.listdir(tmp_path) == ["bad.nc"]


def test_refuses_to_overwrite_input(tmp_path):
    src = tmp_path / "p.nc"
    src.write_bytes(SAMPLES.joinpath("pocket.nc").read_bytes())
    r = mtwin("scale", str(src), "--feed", "0.5", "-o", str(src))
    assert r.returncode == 2 and b"--in-place" in r.stderr
    r = mtwin("scale", str(src), "--feed", "0.5", "-o", str(src), "--in-place")
    assert r.returncode == 0 and src.read_bytes() != SAMPLES.joinpath("pocket.nc").read_bytes()


@pytest.mark.parametrize("args", [
    ["parse", "/nonexistent.nc"],
    ["scale", POCKET, "--feed", "-1", "-o", "-"],
    ["verify", POCKET, POCKET, "--tol", "0"],
    ["parse", POCKET, "--dialect", "haas"],
])
def test_usage_errors_exit_2(args):
    r = mtwin(*args)
    assert r.returncode == 2 and b"Traceback" not in r.stderr


def test_twin_file_validation(tmp_path):
    twin = tmp_path / "m.toml"
    twin.write_text("[work_offsets]\nG54 = [1, 2]\n")
    r = mtwin("parse", POCKET, "--twin", str(twin))
    assert r.returncode == 2 and b"work_offsets.G54" in r.stderr
    twin.write_text("[interpreter]\ndialekt = 'fanuc'\n")
    r = mtwin("parse", POCKET, "--twin", str(twin))
    assert r.returncode == 2 and b"interpreter.dialekt" in r.stderr
    twin.write_text("[tool_lengths]\n2 = 80.0\n")
    r = mtwin("parse", POCKET, "--twin", str(twin))
    assert r.returncode == 2 and b"not in the tool table" in r.stderr
