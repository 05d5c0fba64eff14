"""The tool ledger: what each physical tool has cut, its wear, and its calibrated wear law.

A physical tool has an id the user gives (``T3#A1742``) and is mapped to a program's tool
number per run (``--tool-id T3=T3#A1742``).  The ledger holds, per tool, every run recorded
with it (program, tool number, material, path in the material, edge sliding, time in the cut,
volume, the land before and after), the flank-wear law calibrated for it and the journal of
those calibrations (the error before and after each: the error falling).  A tool's history is
the sum of its runs; its wear state is that history under its law (``effects.wear``).

SQLite, from the standard library: several processes (a batch of simulations, two machines'
post-processors) record to one ledger at once and none loses an entry — each write is one
transaction (``BEGIN IMMEDIATE``, waiting for the other writer), a crash leaves the last
committed state, and a file that is not a ledger is refused, never reset.  A TOML file would
need a lock file and a rewrite of the whole file per run.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
import sqlite3
from dataclasses import dataclass

from .effects.base import ToolHistory
from .errors import MtwinError

FORMAT = "mtwin-ledger 1"
#: ISO 8688-2's criterion for the end of an end mill's life: a uniform flank-wear land of 0.3 mm
VB_LIMIT = 0.3
_TIMEOUT = 60.0  # s a writer waits for another

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS tools (id TEXT PRIMARY KEY, created TEXT NOT NULL, law TEXT);
CREATE TABLE IF NOT EXISTS runs (
    n INTEGER PRIMARY KEY AUTOINCREMENT, tool TEXT NOT NULL REFERENCES tools(id), at TEXT NOT NULL,
    program TEXT NOT NULL, tool_number INTEGER NOT NULL, material TEXT NOT NULL,
    length REAL NOT NULL, sliding REAL NOT NULL, time REAL NOT NULL, volume REAL NOT NULL,
    vb_start REAL, vb_end REAL, source TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS calibrations (
    n INTEGER PRIMARY KEY AUTOINCREMENT, tool TEXT NOT NULL REFERENCES tools(id), at TEXT NOT NULL,
    law TEXT NOT NULL, measurement TEXT NOT NULL, rms_before TEXT NOT NULL, rms_after TEXT NOT NULL);
"""


def parse_tool_ids(specs) -> dict[int, str]:
    """``["T3=T3#A1742", "1=EM6-07"]`` -> {3: "T3#A1742", 1: "EM6-07"}."""
    out: dict[int, str] = {}
    for spec in specs or ():
        number, eq, ident = str(spec).partition("=")
        number = number.strip().upper().removeprefix("T")
        if not eq or not number.isdigit() or not ident.strip():
            raise MtwinError(f"--tool-id {spec}: expected T<number>=<tool id>, e.g. T3=T3#A1742")
        if int(number) in out:
            raise MtwinError(f"--tool-id {spec}: tool T{number} is mapped twice")
        out[int(number)] = ident.strip()
    return out


@dataclass
class ToolRecord:
    """One tool as the ledger knows it."""

    id: str
    created: str
    law: dict | None
    history: ToolHistory
    runs: int
    last_run: dict | None

    def wear(self, vb_limit: float = VB_LIMIT) -> dict:
        """The land now, the sliding left to ``vb_limit`` and the parts (runs like the last) it
        leaves — under the tool's law (None where it has none)."""
        if not self.law:
            # no law of its own: the land its last run ended with, under the twin's law then
            vb = (self.last_run or {}).get("vb_end")
            return {"vb": vb, "vb_limit": vb_limit, "sliding_left": None, "parts_left": None}
        from .effects.wear import land, sliding_to

        p = _law(self.law)
        vb = float(land(self.history.sliding, p["vb0"], p))
        left = max(float(sliding_to(vb_limit, vb, p)), 0.0) if vb < vb_limit else 0.0
        per = (self.last_run or {}).get("sliding") or 0.0
        parts = int(left // per) if per > 0 and left != float("inf") else None
        return {"vb": round(vb, 6), "vb_limit": vb_limit, "sliding_left": None if left == float("inf") else
                round(left, 6), "parts_left": parts}


_AMOUNTS = ("length", "sliding", "time", "volume")  # what a run cut: finite and >= 0
_LANDS = ("vb_start", "vb_end")  # mm, finite and >= 0, or none recorded


# the most one run of one part may hold: 1,000 km of path, 1e6 s, 1e9 mm^3, a 10-mm land (the
# params' own bounds per unit); beyond them a number is an edit or damage, not a run
_RUN_MAX = {"length": 1e9, "sliding": 1e9, "time": 1e6, "volume": 1e9, "vb_start": 10.0, "vb_end": 10.0}


def _check_run(d: dict, path: str, ident: str) -> None:
    """A run's numbers as the ledger writes them, or an error naming the run (a file edited by
    hand, or damaged: never a silently wrong total)."""
    for k in _AMOUNTS + _LANDS:
        v = d[k]
        if v is None and k in _LANDS:
            continue
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not 0 <= v <= _RUN_MAX[k]:
            raise MtwinError(f"{path}: tool {ident!r}, run {d['n']}: {k} = {v!r} is not a number from 0 to "
                             f"{_RUN_MAX[k]:g} (the ledger was changed by hand or damaged)")


def _law(values: dict) -> dict:
    from .effects.wear import FlankWear

    return FlankWear(**values).resolved()


_TABLES = {"meta", "tools", "runs", "calibrations"}


def _create(path: str) -> None:
    """A new, empty ledger at ``path``, made whole beside it and linked into place: a process
    that opens the path at the same moment finds either no file or a whole ledger (of two
    creating it at once, the first link wins and the other opens that one)."""
    import tempfile

    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".mtwin-ledger-", suffix=".db", dir=folder)
    os.close(fd)
    try:
        db = sqlite3.connect(tmp, isolation_level=None)
        try:
            for stmt in filter(None, (s.strip() for s in _SCHEMA.split(";"))):
                db.execute(stmt)
            db.execute("INSERT INTO meta VALUES ('format', ?)", (FORMAT,))
        finally:
            db.close()
        try:
            os.link(tmp, path)
        except FileExistsError:
            pass
        except OSError:  # a file system without hard links: a rename (the race is then open)
            if not os.path.exists(path):
                os.replace(tmp, path)
                return
    except sqlite3.DatabaseError as exc:
        raise MtwinError(f"{path}: cannot create the tool ledger ({exc})") from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _check_schema(db, path: str) -> None:
    """The ledger's tables and format, or an error that leaves the file alone."""
    have = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")} - {"sqlite_sequence"}
    if have != _TABLES:
        missing, extra = sorted(_TABLES - have), sorted(have - _TABLES)
        why = "; ".join(x for x in (f"no table {', '.join(missing)}" if missing else "",
                                    f"tables a ledger has not: {', '.join(extra)}" if extra else "") if x)
        raise MtwinError(f"{path}: an SQLite file, but not an mtwin tool ledger ({why}); it is left as it is")
    row = db.execute("SELECT value FROM meta WHERE key='format'").fetchone()
    if row is None:
        raise MtwinError(f"{path}: an SQLite file with a ledger's tables but no format stamp: not written by mtwin; "
                         f"it is left as it is")
    if row[0] != FORMAT:
        raise MtwinError(f"{path}: a tool ledger of format {row[0]!r}; this mtwin reads {FORMAT!r}")


class Ledger:
    """A tool ledger file (created on the first write)."""

    def __init__(self, path: str, *, create: bool = True):
        """Open the ledger at ``path``.  Only a file whose tables are the ledger's (and whose
        format it names) is accepted: any other file — a foreign SQLite database, one with a
        table dropped, an empty file — is refused and left byte for byte as it was.  A new
        ledger is created only where no file exists and ``create`` is set (a command that
        records); a reading command never writes."""
        self.path = str(path)
        if not os.path.exists(self.path):
            if not create:
                raise MtwinError(f"{self.path}: no such tool ledger (one is created by simulate/optimize --record)")
            _create(self.path)
        if os.path.getsize(self.path) == 0:
            raise MtwinError(f"{self.path}: an empty file, not an mtwin tool ledger; it is left as it is — give a "
                             f"new --ledger path (a ledger is created where no file exists)")
        try:
            # read-only first: a file that is not a ledger is never written
            from pathlib import Path

            ro = sqlite3.connect(f"{Path(self.path).resolve().as_uri()}?mode=ro", uri=True, timeout=_TIMEOUT)
            try:
                _check_schema(ro, self.path)
            finally:
                ro.close()
            self._db = sqlite3.connect(self.path, timeout=_TIMEOUT, isolation_level=None)
        except sqlite3.DatabaseError as exc:
            raise MtwinError(f"{self.path}: not a readable tool ledger ({exc}); it is left as it is — restore it "
                             f"from a backup or give another --ledger file") from None

    def close(self) -> None:
        self._db.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _write(self):
        db = self._db

        class _Tx:
            def __enter__(self_):
                db.execute("BEGIN IMMEDIATE")  # the write lock now: another writer waits

            def __exit__(self_, kind, value, tb):
                db.execute("COMMIT" if kind is None else "ROLLBACK")
                return False

        return _Tx()

    # ---------------------------------------------------------------- reading
    def ids(self) -> list[str]:
        return [r[0] for r in self._db.execute("SELECT id FROM tools ORDER BY id")]

    def tool(self, ident: str) -> ToolRecord:
        row = self._db.execute("SELECT id, created, law FROM tools WHERE id=?", (ident,)).fetchone()
        if row is None:
            raise MtwinError(f"{self.path}: no tool {ident!r} (tools: {', '.join(self.ids()) or 'none yet'})")
        last = self.runs(ident)[-1:]  # (every run's numbers checked)
        s = self._db.execute("SELECT COUNT(*), COALESCE(SUM(length),0), COALESCE(SUM(sliding),0), "
                             "COALESCE(SUM(time),0), COALESCE(SUM(volume),0) FROM runs WHERE tool=?",
                             (ident,)).fetchone()
        return ToolRecord(row[0], row[1], json.loads(row[2]) if row[2] else None,
                          ToolHistory(s[1], s[2], s[3], s[4]), int(s[0]), last[0] if last else None)

    def history(self, ident: str) -> ToolHistory:
        """What the tool has cut (a new id: nothing)."""
        return self.tool(ident).history if ident in self.ids() else ToolHistory()

    def runs(self, ident: str) -> list[dict]:
        cols = ("n", "at", "program", "tool_number", "material", "length", "sliding", "time", "volume", "vb_start",
                "vb_end", "source")
        out = [dict(zip(cols, r)) for r in self._db.execute(
            f"SELECT {', '.join(cols)} FROM runs WHERE tool=? ORDER BY n", (ident,))]
        for d in out:
            _check_run(d, self.path, ident)
        return out

    def calibrations(self, ident: str) -> list[dict]:
        cols = ("n", "at", "law", "measurement", "rms_before", "rms_after")
        out = []
        for r in self._db.execute(f"SELECT {', '.join(cols)} FROM calibrations WHERE tool=? ORDER BY n", (ident,)):
            d = dict(zip(cols, r))
            for k in ("law", "rms_before", "rms_after"):
                d[k] = json.loads(d[k])
            out.append(d)
        return out

    # ---------------------------------------------------------------- writing
    def _ensure(self, ident: str) -> None:
        self._db.execute("INSERT OR IGNORE INTO tools (id, created) VALUES (?, ?)", (ident, _now()))

    def record(self, ident: str, *, program: str, tool_number: int, material: str, use: ToolHistory,
               vb_start: float | None = None, vb_end: float | None = None, source: str = "simulate") -> None:
        """Add one run of a program to the tool's history."""
        with self._write():
            self._insert_run(ident, program=program, tool_number=tool_number, material=material, use=use,
                             vb_start=vb_start, vb_end=vb_end, source=source)

    def _insert_run(self, ident: str, *, program: str, tool_number: int, material: str, use: ToolHistory,
                    vb_start, vb_end, source: str) -> None:
        # (inside a transaction of the caller's; a run the ledger would refuse to read back is not
        # written: the transaction is rolled back, nothing recorded)
        _check_run({"n": "new", "length": use.length, "sliding": use.sliding, "time": use.time,
                    "volume": use.volume, "vb_start": vb_start, "vb_end": vb_end}, self.path, ident)
        self._ensure(ident)
        self._db.execute("INSERT INTO runs (tool, at, program, tool_number, material, length, sliding, time, "
                         "volume, vb_start, vb_end, source) VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
                         (ident, _now(), program, int(tool_number), material, use.length, use.sliding, use.time,
                          use.volume, vb_start, vb_end, source))

    def set_law(self, ident: str, law: dict, *, measurement: str, rms_before: dict, rms_after: dict) -> None:
        """The tool's wear law from a calibration, with its journal entry."""
        _law(law)  # checked against the effect's declarations
        with self._write():
            self._ensure(ident)
            self._db.execute("UPDATE tools SET law=? WHERE id=?", (json.dumps(law), ident))
            self._db.execute("INSERT INTO calibrations (tool, at, law, measurement, rms_before, rms_after) "
                             "VALUES (?,?,?,?,?,?)", (ident, _now(), json.dumps(law), measurement,
                                                      json.dumps(rms_before), json.dumps(rms_after)))


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def apply(twin, ledger_path: str, tool_ids: dict[int, str]):
    """The twin with each mapped tool starting in its recorded state and, where the ledger has
    a calibrated law for one, that flank-wear law (the twin has one: the first mapped tool's
    with a law)."""
    from .effects.wear import FlankWear

    records = {}
    if os.path.exists(ledger_path):  # (a ledger not yet written: new tools; --record creates it)
        with Ledger(ledger_path, create=False) as lg:
            known = set(lg.ids())
            records = {n: lg.tool(i) for n, i in tool_ids.items() if i in known}
    twin = twin.with_tool_state({n: records[n].history if n in records else ToolHistory() for n in tool_ids})
    law = next((r.law for r in records.values() if r.law), None)
    if law:
        effects = [e for e in twin.effects if e.name != FlankWear.name] + [FlankWear(**law)]
        twin = twin.replace(effects=effects)
    return twin


def run_use(tool_ids: dict[int, str], trace) -> list[tuple]:
    """What one simulated run cut with each mapped tool: (id, tool number, use, VB start, VB end)."""
    use = trace.tool_use or {}
    c = trace.summary.cutting
    wear = c.tool_wear if c is not None else {}
    return [(ident, number, use[number], wear.get(number, {}).get("vb_start"), wear.get(number, {}).get("vb_end"))
            for number, ident in tool_ids.items() if number in use]


def record_traces(ledger_path: str, runs: list, *, program: str, material: str,
                  source: str = "simulate") -> list[str]:
    """Record several runs (``run_use`` of each) in one transaction: all of them or none."""
    done: list[str] = []
    with Ledger(ledger_path) as lg:
        with lg._write():
            for per_run in runs:
                for ident, number, use, vb0, vb1 in per_run:
                    lg._insert_run(ident, program=program, tool_number=number, material=material, use=use,
                                   vb_start=vb0, vb_end=vb1, source=source)
                    if ident not in done:
                        done.append(ident)
    return done


def record_trace(ledger_path: str, tool_ids: dict[int, str], trace, *, program: str, material: str | None = None,
                 source: str = "simulate") -> list[str]:
    """Record what a simulated run cut with each mapped tool; returns the ids recorded."""
    c = trace.summary.cutting
    material = material if material is not None else (c.material if c is not None else "")
    return record_traces(ledger_path, [run_use(tool_ids, trace)], program=program, material=material, source=source)
