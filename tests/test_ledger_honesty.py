"""Ledger honesty (issue 33, item 5): only a file whose schema is the ledger's is accepted, and
any other is left byte for byte as it was; a batch of runs is recorded all or nothing."""
from __future__ import annotations

import sqlite3

import pytest

from mtwin.cli import run_command
from mtwin.errors import MtwinError
from mtwin.ledger import Ledger

PROG = "(T1 D=6 CR=0 - flat end mill)\n(MTWIN STOCK -10,-10,-5,40,10,0)\nG21 G90 G17\nT1 M6\nS8000 M3\n" \
       "G0 X-5 Y0 Z5\nG0 Z-1\nG1 X30 F300\nG0 Z5\nM30\n"


def _foreign(path):
    db = sqlite3.connect(path)
    db.executescript("CREATE TABLE meta (key TEXT, value TEXT); CREATE TABLE tools (id TEXT); "
                     "INSERT INTO meta VALUES ('owner', 'accounts');")
    db.commit()
    db.close()


def _dropped(path):
    with Ledger(str(path)) as lg:
        lg.ids()
    db = sqlite3.connect(path)
    db.execute("DROP TABLE runs")
    db.commit()
    db.close()


@pytest.mark.parametrize("make,why", [
    (_foreign, "not an mtwin tool ledger (no table calibrations, runs)"),
    (_dropped, "not an mtwin tool ledger (no table runs)"),
    (lambda p: p.write_bytes(b""), "an empty file, not an mtwin tool ledger"),
    (lambda p: p.write_bytes(b"SQLite format 3\x00" + b"\x07" * 200), "not a readable tool ledger"),
])
@pytest.mark.parametrize("command", ["tools", "record"])
def test_a_file_that_is_not_a_ledger_is_refused_and_left_as_it_was(tmp_path, make, why, command):
    led = tmp_path / "l.db"
    make(led)
    before = led.read_bytes()
    prog = tmp_path / "p.nc"
    prog.write_text(PROG)
    args = (["tools", "--ledger", str(led)] if command == "tools" else
            ["simulate", str(prog), "--ledger", str(led), "--tool-id", "T1=EM-1", "--record"])
    code, out, err = run_command(args)
    assert code == 2 and why in err, err
    assert led.read_bytes() == before
    with pytest.raises(MtwinError, match="left as it is"):
        Ledger(str(led))


def test_a_reading_command_never_creates_a_ledger(tmp_path):
    led = tmp_path / "none.db"
    code, _, err = run_command(["tools", "--ledger", str(led)])
    assert code == 2 and "no such tool ledger" in err and not led.exists()


def test_runs_are_recorded_all_or_none_and_bounded(tmp_path, monkeypatch):
    prog = tmp_path / "p.nc"
    prog.write_text(PROG)
    led = tmp_path / "l.db"
    code, _, err = run_command(["simulate", str(prog), "--ledger", str(led), "--tool-id", "T1=EM-1", "--record",
                                "--runs", "3"])
    assert code == 0, err
    with Ledger(str(led)) as lg:
        assert len(lg.runs("EM-1")) == 3
    before = led.read_bytes()
    # interrupted in the third run of five: nothing of the five is recorded
    import mtwin.twin as T

    real = T.Twin.simulate_batch

    def interrupted(self, program, runs, **kw):
        on_run = kw.pop("on_run")

        def each(k, tr):
            if k == 3:
                raise KeyboardInterrupt
            on_run(k, tr)

        return real(self, program, runs, on_run=each, **kw)

    monkeypatch.setattr(T.Twin, "simulate_batch", interrupted)
    code, _, err = run_command(["simulate", str(prog), "--ledger", str(led), "--tool-id", "T1=EM-1", "--record",
                                "--runs", "5"])
    assert code == 130
    with Ledger(str(led)) as lg:
        assert len(lg.runs("EM-1")) == 3
    assert led.read_bytes() == before
    code, _, err = run_command(["simulate", str(prog), "--runs", "1000000000"])
    assert code == 2 and "over 10,000 runs" in err


@pytest.mark.parametrize("column, value", [("vb_end", "nan"), ("length", 1e400), ("time", -1.0), ("sliding", "x")])
def test_a_run_whose_numbers_are_not_finite_is_an_error_not_a_total(tmp_path, column, value):
    # a ledger edited by hand or damaged: a NaN land crashed the table (exit 3), an infinite
    # one printed JSON's Infinity, a NaN time counted as 0 s in the cut
    prog = tmp_path / "p.nc"
    prog.write_text(PROG)
    led = tmp_path / "l.db"
    code, _, err = run_command(["simulate", str(prog), "--ledger", str(led), "--tool-id", "T1=EM-1", "--record"])
    assert code == 0, err
    db = sqlite3.connect(led)
    db.execute(f"UPDATE runs SET {column} = ?", (value,))
    db.commit()
    db.close()
    for args in (["tools", "--ledger", str(led)], ["tools", "--ledger", str(led), "--json"]):
        code, out, err = run_command(args)
        assert code == 2 and f"run 1: {column} = " in err and "Infinity" not in out, (args, err)
