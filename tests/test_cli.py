"""The real CLI, run as a subprocess: exit codes, streams, atomic output, JSON keys; outputs a
user reads (tables when piped, config check, Ctrl-C, the --lenient hint)."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from conftest import ROOT, SAMPLES

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


def _cli(*args, **kw):
    """The command in a process of its own, text out (the outputs a user sees)."""
    return subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True, **kw)


def test_tables_are_not_cut_when_piped(tmp_path):
    d = tmp_path / "a_rather_long_directory_name_for_the_shop_floor_programs" / "and_one_more_level_of_them"
    d.mkdir(parents=True)
    (d / "pocket_with_a_long_name.nc").write_bytes((ROOT / "samples" / "pocket.nc").read_bytes())
    r = _cli("simulate", str(d / "pocket_with_a_long_name.nc"), env={**__import__("os").environ, "COLUMNS": ""})
    assert r.returncode == 0, r.stderr
    assert str(d / "pocket_with_a_long_name.nc") in r.stderr  # not broken mid-word at 80 columns
    assert max(len(x) for x in r.stderr.splitlines()) > 80


def test_config_check_describes_the_files_machine(tmp_path):
    (tmp_path / "my.toml").write_text("[spindle]\nmax_speed = 42000.0\nrated_power = 15000.0\n")
    r = _cli("config", "check", str(tmp_path / "my.toml"))
    assert r.returncode == 0, r.stderr
    assert "15 kW / 42,000 rpm" in r.stderr and "11 kW" not in r.stderr and "mtwin default" not in r.stderr
    named = tmp_path / "named.toml"
    named.write_text('[machine]\nname = "Haas VF-2"\n')
    assert "Haas VF-2" in _cli("config", "check", str(named)).stderr


def test_ctrl_c_says_so_and_writes_nothing(tmp_path):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_motion import make_program

    (tmp_path / "big.nc").write_bytes(make_program(60000))
    # (SIGINT restored for the child: a test run started in the background ignores it, and a
    # process that starts with SIGINT ignored keeps ignoring it)
    p = subprocess.Popen([sys.executable, "-m", "mtwin", "optimize", str(tmp_path / "big.nc"), "-o",
                          str(tmp_path / "o.nc")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(4.0)  # (past start-up: the run is simulating or searching)
    if p.poll() is not None:
        pytest.skip("the run finished before the signal")
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err[-500:]
    assert "interrupted (Ctrl-C): no output is left half-written" in err
    assert not (tmp_path / "o.nc").exists() and not list(tmp_path.glob("*.tmp*"))


def test_lenient_is_offered_only_where_it_helps(tmp_path):
    (tmp_path / "a.nc").write_text("G21 G90\nG0 X0 Y0\nG1 X5 Y5 F100 G13.7\nM30\n")
    (tmp_path / "b.nc").write_text("G21 G90\nG0 X0 Y0\nG13.7\nM30\n")
    a = _cli("parse", str(tmp_path / "a.nc"))
    assert a.returncode == 2 and "--lenient does not pass over it" in a.stderr
    b = _cli("parse", str(tmp_path / "b.nc"))
    assert b.returncode == 2 and "--lenient passes over codes that do not move the tool" in b.stderr
    assert _cli("parse", str(tmp_path / "b.nc"), "--lenient").returncode == 0
    c = _cli("parse", str(tmp_path / "a.nc"), "--lenient")
    assert c.returncode == 2 and "even with --lenient" in c.stderr
