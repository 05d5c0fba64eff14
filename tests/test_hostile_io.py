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
    # the way out offered is one the command has: --in-place (optimize's and scale's) allows only
    # the program itself as the output
    assert "--in-place" not in err, err
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


def _server(reply: bytes):
    """A TCP server on a free port that accepts and answers ``reply`` (nothing: never answers)."""
    import socket
    import threading

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    held = []

    def serve():
        while True:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            held.append(c)
            if reply:
                c.sendall(reply)

    threading.Thread(target=serve, daemon=True).start()
    return srv


@pytest.mark.parametrize("reply,limit", [(b"", 20.0), (b"\xff" * 64 + bytes(range(256)) * 4, 20.0)])
def test_a_scheduler_that_never_answers_or_answers_junk_is_given_up(files, reply, limit):
    pytest.importorskip("distributed")
    d, prog, _ = files
    (d / "m.csv").write_text(f"program\n{prog}\n")
    srv = _server(reply)
    try:
        port = srv.getsockname()[1]
        code, err, secs = run("batch", "simulate", "--manifest", d / "m.csv", "-o", d / "out", "--scheduler",
                              f"tcp://127.0.0.1:{port}", env={"MTWIN_SCHEDULER_TIMEOUT": "3"}, timeout=120)
    finally:
        srv.close()
    assert code == 2 and "cannot reach the Dask scheduler" in err and "Traceback" not in err, err
    assert secs < limit
    assert not (d / "out").exists() or not any((d / "out").iterdir())


@pytest.mark.parametrize("signame", ["SIGTERM", "SIGHUP"])
def test_sigterm_leaves_no_temporary_file(files, signame):
    import signal

    d, prog, _ = files
    big = d / "big.nc"
    lines = ["(T1 D=6 CR=0 - flat end mill)", "G21 G90 G17", "T1 M6", "S8000 M3", "G0 X0 Y0 Z5", "G1 Z-1 F300"]
    lines += [f"G1 X{(i % 2) * 50} Y{i * 0.05:.2f} F3000" for i in range(400)]  # (a 6.7-min trace)
    big.write_text("\n".join(lines + ["M30"]) + "\n")
    out = d / "trace.csv"
    # (the child starts with the signal's default action: under nohup SIGHUP comes ignored, and
    # mtwin leaves an ignored SIGHUP ignored on purpose)
    p = subprocess.Popen([sys.executable, "-m", "mtwin", "simulate", str(big), "-o", str(out)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         preexec_fn=lambda: signal.signal(getattr(signal, signame), signal.SIG_DFL))
    # wait until the output's temporary file (.trace.csv.XXXX.tmp) exists, then terminate
    t0 = time.monotonic()
    seen = False
    while time.monotonic() - t0 < 120 and p.poll() is None:
        if any(x.name.startswith(".trace.csv.") for x in d.iterdir()):
            seen = True
            break
        time.sleep(0.01)
    if not seen:
        p.kill()
        pytest.skip("the run ended before its output was being written: nothing to interrupt")
    p.send_signal(getattr(signal, signame))
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130
    assert f"interrupted ({signame}" in err.decode() and "Ctrl-C" not in err.decode()  # (named as it came)
    left = [x.name for x in d.iterdir() if x.name not in {"p.nc", "t.toml", "big.nc"}]
    assert left == [], left  # (no temporary file, and no half-written trace.csv)


def test_a_batch_refuses_an_output_folder_that_holds_its_inputs(tmp_path):
    bt = tmp_path / "bt"
    (bt / "j").mkdir(parents=True)
    (bt / "j" / "ga.nc").write_bytes(PROG)
    (bt / "m.csv").write_text("name,program\nj,j/ga.nc\n")
    before = _snapshot(bt)
    before_j = _snapshot(bt / "j")
    code, err, _ = run("batch", "optimize", "--manifest", bt / "m.csv", "-o", bt)
    assert code == 2 and "the output folder holds an input of the batch" in err, err
    assert _snapshot(bt) == before and _snapshot(bt / "j") == before_j


def test_inputs_are_read_in_pieces_up_to_their_limit(monkeypatch):
    # read(limit + 1) reserved the whole limit (4 GB for a measurement) before a byte came; in
    # pieces it holds what it read, and a stream past the limit stops one byte over it
    import io

    from mtwin import io as mio

    class Stream(io.RawIOBase):
        asked = []

        def readable(self):
            return True

        def readinto(self, b):
            self.asked.append(len(b))
            b[:] = b"\0" * len(b)
            return len(b)

    s = io.BufferedReader(Stream(), buffer_size=4096)
    data = mio._read_within(s, 3 * 1048576)
    assert len(data) == 3 * 1048576 + 1 and max(Stream.asked) <= 1048576
    # the measurement on stdin: the limit applies there too, with the limit's message
    monkeypatch.setenv("MTWIN_MAX_MEASUREMENT_MB", "1")
    monkeypatch.setattr("sys.stdin", io.TextIOWrapper(io.BufferedReader(Stream())))
    with pytest.raises(mio.MtwinError, match="over the 1 MB a measurement may have"):
        mio.read_input("-", "measurement")


def test_a_trace_is_written_in_blocks_the_same_bytes(tmp_path, monkeypatch):
    # written whole, a 4-hour trace took 650 bytes a sample beside the trace itself; in blocks the
    # file is the same to the byte (a log's empty line cells included)
    import numpy as np

    import mtwin.motion.trace as T

    cols = {"t": np.arange(1000) * 0.001, "line": np.where(np.arange(1000) < 10, -1, 7),
            "x_cmd": np.linspace(0, 1, 1000)}
    T.write_columns(tmp_path / "a.csv", cols)
    monkeypatch.setattr(T, "WRITE_ROWS", 64)
    T.write_columns(tmp_path / "b.csv", cols)
    a = (tmp_path / "a.csv").read_bytes()
    assert a == (tmp_path / "b.csv").read_bytes() and b"\n0.009000000,,0.00900900900901\n" in a


def test_a_value_that_is_not_finite_is_written_as_missing(tmp_path):
    # a vibration past divergence (--dynamics) was written 'inf'/'nan', which mtwin's own reader
    # then refused: it is missing, and reads back so
    import numpy as np

    import mtwin.motion.trace as T
    from mtwin.loop.measurement import read_measurement

    cols = {"t": np.arange(4) * 0.001, "line": np.array([1, 1, 2, 2]), "vib_x": np.array([0.0, 1e-3, np.inf, np.nan])}
    T.write_columns(tmp_path / "d.csv", cols)
    assert (tmp_path / "d.csv").read_text().splitlines()[-2:] == ["0.002000000,2,", "0.003000000,2,"]
    m = read_measurement(str(tmp_path / "d.csv"))
    assert m.signals["vib_x"][:2].tolist() == [0.0, 1e-3] and np.isnan(m.signals["vib_x"][2:]).all()


def test_a_trace_too_large_for_memory_names_the_programs_length_in_its_own_units():
    # (a short program at a tiny servo period: "a trace of 0.0 h" told the user nothing)
    from dataclasses import replace

    import mtwin
    from mtwin.errors import MtwinError

    tw = mtwin.Twin()
    tw = tw.replace(machine=replace(tw.machine, controller=replace(tw.machine.controller, servo_period=1e-6)))  # (the shortest a twin file takes)
    prog = tw.load(b"G21 G90 G94\nG1 X200 F200\nM30\n", path="short.nc")
    with pytest.raises(MtwinError) as exc:
        tw.simulate(prog, cutting=False)
    assert "a trace of 1.0 min at every 1 servo sample" in str(exc.value) and "0.0 h" not in str(exc.value), str(exc.value)


def test_a_binary_file_is_refused_at_its_first_control_byte_without_a_whole_file_scan(monkeypatch):
    # a 300-MB file of NULs took 13.9 s: the lexer stopped at byte 1, and the macro scan then ran
    # eleven regular expressions over the whole file before the same error came out
    from mtwin.errors import GCodeError
    from mtwin.gcode import interpreter, macro

    def scanned(data):
        raise AssertionError("the whole-file macro scan ran on a binary file")

    monkeypatch.setattr(macro, "looks_like_macro", scanned)
    with pytest.raises(GCodeError, match="unexpected byte 0x00 outside a comment") as e:
        interpreter.load_program(b"\x00" * 1_000_000, path="nul.nc")
    assert str(e.value).startswith("nul.nc:1:1:")
    # a control byte in a comment is no error, and a macro program still reaches the macro path
    assert len(interpreter.load_program(b"G21 G90 (a \x01 here)\nG1 X1 F100\nM2\n").records) > 0
    monkeypatch.undo()
    with pytest.raises(GCodeError, match="3:12"):
        interpreter.load_program(b"#1=1\nG21 G90\nG1 X#1 F100\x00\nM2\n", path="m.nc")
