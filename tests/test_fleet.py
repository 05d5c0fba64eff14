"""mtwin batch: a fleet's jobs give the single commands' outputs byte for byte — one by one in a
process, on a separately started Dask scheduler with two workers, and with a worker killed
mid-batch; failures are listed with their message; bad input writes nothing; the summary page
renders in headless Chromium; a fleet calibration finds the machine that differs."""
from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REALDATA, SAMPLES

TWINS = [SAMPLES / "machines" / "hurco-vmx24.toml", SAMPLES / "machines" / "linuxcnc-sim.toml"]
# real programs small enough for the suite (their folders' SOURCE.txt say where they are from);
# vertical-slot.ngc asks linuxcnc-sim for a tool length it has not: a job that fails, with its message
REAL = [REALDATA / "gcode_corpus" / "pygcode_test_files" / "vertical-slot.ngc",
        REALDATA / "gcode_corpus" / "fusion360_led_floor" / "1105_bore_test_27bit_35_diam_80feed.nc"]
BROKEN = "G21 G90\nG1 X10 Y0 F\nM30\n"


def mtwin(*args, env=None, **kw):
    return subprocess.run([sys.executable, "-m", "mtwin", *map(str, args)], capture_output=True, text=True,
                          env=env, **kw)


def single(command: str, *args) -> tuple[int, str]:
    """The command alone, in this process (not the batch's code path: the CLI's own main)."""
    from typer.testing import CliRunner

    from mtwin.cli import app

    r = CliRunner().invoke(app, [command, *map(str, args)])
    return r.exit_code, r.output


def _manifest(tmp: Path, programs, twins, name="jobs.csv") -> Path:
    m = tmp / name
    with m.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["program", "twin"])
        for p in programs:
            for t in twins:
                w.writerow([str(p), str(t)])
    return m


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """A batch optimize over the samples (and the real programs where ../shared is present) × two
    twin files, one by one in a process of its own; the jobs' names, the folder, the result."""
    tmp = tmp_path_factory.mktemp("fleet")
    broken = tmp / "broken.nc"
    broken.write_text(BROKEN)
    programs = [SAMPLES / "pocket.nc", SAMPLES / "contour.nc", broken] + [p for p in REAL if p.is_file()]
    m = _manifest(tmp, programs, TWINS)
    r = mtwin("batch", "optimize", "--manifest", m, "-o", tmp / "out", "--workers", "0", "--json")
    return {"tmp": tmp, "manifest": m, "out": tmp / "out", "run": r, "doc": json.loads(r.stdout or "{}"),
            "programs": programs}


def test_batch_optimize_equals_the_single_commands_byte_for_byte(fleet, tmp_path):
    r, doc = fleet["run"], fleet["doc"]
    assert r.returncode == 1, r.stderr  # the broken program (and a program off a machine's travel) failed
    jobs = {j["name"]: j for j in doc["jobs"]}
    assert len(jobs) == len(fleet["programs"]) * 2
    assert set(doc["summary"]) >= {"jobs", "ok", "failed", "refused", "machines", "cycle_saved_s"}
    failed = [j for j in jobs.values() if j["status"] != "ok"]
    broken = [j for j in failed if j["program"].endswith("broken.nc")]
    assert len(broken) == 2 and all("broken.nc:2:" in j["error"] for j in broken)  # file:line:col, as alone
    if REAL[0].is_file():
        slot = jobs["vertical-slot@linuxcnc-sim"]
        assert slot["status"] == "failed" and "vertical-slot.ngc:1:1: tool length offset" in slot["error"]
    for j in failed:  # listed with their message on stderr
        assert f"{j['name']} {j['status']}: {j['error']}" in r.stderr
    ok = [j for j in jobs.values() if j["status"] == "ok"]
    assert len(ok) >= 4
    for j in ok:
        prog, rep = tmp_path / "p.nc", tmp_path / "r.html"
        code, out = single("optimize", j["program"], "--twin", j["twin"], "-o", prog, "--report", rep)
        assert code == 0, out
        assert Path(j["outputs"]["program"]).read_bytes() == prog.read_bytes(), j["name"]
        assert Path(j["outputs"]["report"]).read_bytes() == rep.read_bytes(), j["name"]
        assert j["before"]["cycle_time"] >= j["after"]["cycle_time"] > 0
    rows = list(csv.DictReader((fleet["out"] / "summary.csv").open()))
    assert [row["job"] for row in rows] == [j["name"] for j in doc["jobs"]]
    assert {row["status"] for row in rows} == {"ok", "failed"}


def test_summary_page_renders_in_headless_chromium(fleet):
    from test_optimize_report import CHROMIUM

    if CHROMIUM is None:
        pytest.skip("no headless Chromium on this machine (Debian: apt-get install chromium)")
    page = fleet["out"] / "index.html"
    run = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr", "--v=0",
                          "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120)
    dom = run.stdout
    assert [ln for ln in run.stderr.splitlines() if ":CONSOLE" in ln or "Uncaught" in ln] == []
    assert "cycle time saved per machine" in dom and dom.count("<rect") == 2  # one bar per machine
    for j in fleet["doc"]["jobs"]:
        assert j["name"] in dom
    assert "Failed and refused jobs" in dom and "broken.nc:2:" in dom
    assert "http" not in dom.replace("http://www.w3.org/2000/svg", "")  # self-contained: nothing fetched


def test_a_job_on_a_worker_without_the_files_runs_on_their_copy(tmp_path):
    """A worker that does not see the client's files runs the job on the copy that travelled
    with the task: relative paths keep their names, so the outputs are the same bytes."""
    from mtwin.cli import run_command
    from mtwin.fleet.job import read_inputs, run_job
    from mtwin.fleet.manifest import Job

    here = Job("pocket@default", "optimize", "samples/pocket.nc", base=str(SAMPLES.parent))
    a = run_job(here, read_inputs(here), (), run_command)
    away = Job("pocket@default", "optimize", "samples/pocket.nc", base=str(tmp_path / "not-on-this-worker"))
    b = run_job(away, read_inputs(here), (), run_command)
    assert a.status == b.status == "ok"
    assert a.outputs == b.outputs and b"samples/pocket.nc" in a.outputs["report"][1]
    assert os.getcwd() != str(tmp_path) and not list(tmp_path.iterdir())


def test_without_dask_the_batch_runs_in_process_and_says_how_to_get_parallelism(tmp_path):
    code = ("import sys, mtwin.fleet.runner as r; r.have_dask = lambda: False\n"
            "from mtwin.cli import main\nsys.argv = ['mtwin', *sys.argv[1:]]\nmain()")
    r = subprocess.run([sys.executable, "-c", code, "batch", "simulate", str(SAMPLES / "drilling.nc"),
                        "-o", str(tmp_path / "o"), "--no-cutting"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "pip install 'mtwin[fleet]'" in r.stderr
    doc = json.loads((tmp_path / "o" / "drilling@default" / "simulate.json").read_text())
    alone = mtwin("simulate", SAMPLES / "drilling.nc", "--no-cutting", "--json")
    assert doc == json.loads(alone.stdout)


@pytest.mark.parametrize("case", ["missing", "duplicate", "column", "option", "scheduler"])
def test_bad_input_exits_2_and_writes_nothing(tmp_path, case):
    pocket = SAMPLES / "pocket.nc"
    m = tmp_path / "jobs.csv"
    extra = []
    if case == "missing":
        m.write_text(f"program,twin\n{pocket},\n{tmp_path / 'nope.nc'},\n")
        want = f"{m}:3:1: program"
    elif case == "duplicate":
        m.write_text(f"program,twin\n{pocket},{TWINS[0]}\n{pocket},{TWINS[0]}\n")
        want = f"{m}:3: duplicate job"
    elif case == "column":
        m.write_text(f"program,twin,feedrate\n{pocket},,100\n")
        want = f"{m}:1:14: unknown column 'feedrate'"
    elif case == "option":
        m.write_text(f"program,options\n{pocket},--objective time --output x.nc\n")
        want = "--output is the batch's to set"
    else:
        m.write_text(f"program\n{pocket}\n")
        pytest.importorskip("distributed")
        extra = ["--scheduler", "tcp://127.0.0.1:9"]  # (port 9: discard, nothing listens)
        want = "cannot reach the Dask scheduler at tcp://127.0.0.1:9"
    r = mtwin("batch", "optimize", "--manifest", m, "-o", tmp_path / "out", *extra)
    assert r.returncode == 2, r.stderr
    assert want in r.stderr
    assert not (tmp_path / "out").exists()


def test_manifest_in_toml_and_options_per_job(tmp_path):
    from mtwin.fleet import read_manifest

    m = tmp_path / "jobs.toml"
    m.write_text(f'[[job]]\nprogram = "{SAMPLES / "pocket.nc"}"\ntwin = "{TWINS[0]}"\noptions = ["--objective", "cost"]\n'
                 f'[[job]]\nprogram = "{SAMPLES / "pocket.nc"}"\nname = "plain"\n')
    jobs = read_manifest(str(m), "optimize")
    assert [j.name for j in jobs] == ["pocket@hurco-vmx24", "plain"]
    assert jobs[0].options == ("--objective", "cost") and jobs[1].twin is None


# ---------------------------------------------------------------------- on a Dask cluster


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A `dask scheduler` and two `dask worker` processes, started here (no nanny: a killed
    worker stays dead), their scheduler file."""
    pytest.importorskip("distributed")
    tmp = tmp_path_factory.mktemp("cluster")
    sched_file = tmp / "scheduler.json"
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "MTWIN_BACKGROUND_COMPILE": "0"}
    procs = [subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(sched_file)], env=env, cwd=tmp,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    t0 = time.time()
    while not sched_file.exists() and time.time() - t0 < 60:
        time.sleep(0.2)
    for k in range(2):
        procs.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", "--scheduler-file",
                                       str(sched_file), "--nthreads", "1", "--no-nanny", "--no-dashboard",
                                       "--name", f"w{k}"], env=env, cwd=tmp, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))
    from distributed import Client

    with Client(scheduler_file=str(sched_file), timeout="60s") as c:
        c.wait_for_workers(2, timeout=60)
    yield {"file": sched_file, "workers": procs[1:]}
    for p in procs:
        p.kill()
        p.wait()


def _same_outputs(doc, fleet_doc, names):
    ref = {j["name"]: j for j in fleet_doc["jobs"]}
    for j in doc["jobs"]:
        if j["name"] not in names:
            continue
        assert j["status"] == ref[j["name"]]["status"] == "ok", j
        for k in ("program", "report"):
            assert Path(j["outputs"][k]).read_bytes() == Path(ref[j["name"]]["outputs"][k]).read_bytes(), j["name"]


def test_separately_started_scheduler_and_two_workers_give_the_same_outputs(fleet, cluster, tmp_path):
    r = mtwin("batch", "optimize", "--manifest", fleet["manifest"], "-o", tmp_path / "out", "--scheduler-file",
              cluster["file"], "--json")
    doc = json.loads(r.stdout)
    assert r.returncode == 1, r.stderr
    assert [j["status"] for j in doc["jobs"]] == [j["status"] for j in fleet["doc"]["jobs"]]
    assert len({j["worker"] for j in doc["jobs"]}) == 2  # both workers ran jobs
    _same_outputs(doc, fleet["doc"], {j["name"] for j in fleet["doc"]["jobs"] if j["status"] == "ok"})


def test_a_worker_killed_mid_batch_loses_nothing_and_writes_nothing_twice(fleet, cluster, tmp_path):
    ok = [Path(p) for p in fleet["programs"] if not p.name.startswith("broken")]
    m = _manifest(tmp_path, ok, TWINS[:1])
    batch = subprocess.Popen([sys.executable, "-m", "mtwin", "batch", "optimize", "--manifest", str(m), "-o",
                              str(tmp_path / "out"), "--scheduler-file", str(cluster["file"]), "--json"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    victim = cluster["workers"][1]
    # the moment the first job is written, both workers are busy: kill one in the middle of its job
    t0 = time.time()
    while not list((tmp_path / "out").glob("*/result.json")) and time.time() - t0 < 120:
        time.sleep(0.05)
    victim.send_signal(signal.SIGKILL)
    victim.wait()
    stdout, stderr = batch.communicate(timeout=300)
    assert batch.returncode == 0, stderr
    doc = json.loads(stdout)
    assert [j["status"] for j in doc["jobs"]] == ["ok"] * len(ok)
    done = [ln.split("] ", 1)[1].split(":")[0] for ln in stderr.splitlines() if ln.startswith("[")]
    assert sorted(done) == sorted(j["name"] for j in doc["jobs"])  # each job written once
    assert sum(f"{victim.pid}" in j["worker"] for j in doc["jobs"]) < len(ok)  # the rest ran on the survivor
    _same_outputs(doc, fleet["doc"], {j["name"] for j in doc["jobs"]})


# ---------------------------------------------------------------------- fleet calibration


def test_fleet_calibration_finds_the_machine_that_differs(tmp_path):
    """Three machines' logs (synthetic: the same spindle, machine c's no-load power 2.5×): batch
    calibrate fits each, and the fleet table shows c at about 2.5× the median; the held-out
    program (a second log of each machine) is predicted too."""
    from mtwin.cli import run_command

    p0 = {"a": 150.0, "b": 160.0, "c": 400.0}
    rows = ["name,program,measurement,holdout"]
    for name, v in p0.items():
        for prog, held in (("pocket", ""), ("contour", "yes")):
            meas = tmp_path / f"{name}-{prog}.csv"
            code, _, err = run_command(["synth", SAMPLES / f"{prog}.nc", "-o", meas, "--effect",
                                        f"spindle-no-load:p0={v},b=0.002", "--signals", "spindle_power", "--rate",
                                        "20", "--noise", "0.01", "--seed", "3"])
            assert code == 0, err
            rows.append(f"{name},{SAMPLES / f'{prog}.nc'},{meas},{held}")
    m = tmp_path / "fleet.csv"
    m.write_text("\n".join(rows) + "\n")
    r = mtwin("batch", "calibrate", "--manifest", m, "-o", tmp_path / "cal", "--workers", "0", "--fit",
              "spindle-no-load", "--json")
    assert r.returncode == 0, r.stderr
    table = {row["machine"]: row for row in csv.DictReader((tmp_path / "cal" / "parameters.csv").open())}
    fitted = {k: float(table[k]["effects.spindle-no-load.p0"]) for k in p0}
    for k, v in p0.items():
        assert fitted[k] == pytest.approx(v, rel=0.05)
        assert (tmp_path / "cal" / k / "twin.toml").is_file()
        assert table[k]["holdout_cycle_error_pct"] != ""
    assert "(2.5" in r.stderr or "(2.4" in r.stderr or "(2.6" in r.stderr  # c against the median (b)
    page = (tmp_path / "cal" / "index.html").read_text()
    body = page[page.index("<body>"):]
    assert "{" not in body and body.count("class='odd'") == 1  # c's no-load power, and nothing else, marked
    assert "effects.spindle-no-load.p0" in page
    doc = json.loads(r.stdout)
    assert all(j["figures"]["fit_measure"] == "spindle_power" and j["figures"]["rms_after"] < j["figures"]["rms_before"]
               for j in doc["jobs"])


@pytest.mark.parametrize("case", ["bom", "name", "measurement", "ledger", "out-file", "scheduler-file"])
def test_more_bad_input_is_a_message_not_a_traceback(tmp_path, case):
    pocket = SAMPLES / "pocket.nc"
    m = tmp_path / "jobs.csv"
    out = tmp_path / "out"
    args = ["--manifest", m, "-o", out]
    if case == "bom":  # a spreadsheet's CSV reads as written: the error here is the missing file, not the header
        m.write_bytes(b"\xef\xbb\xbfprogram,twin,\n" + f"{tmp_path / 'gone.nc'},,\n".encode())
        want = f"{m}:2:1: program"
    elif case == "name":
        m.write_text(f"program,name\n{pocket},summary.csv\n")
        want = "the name 'summary.csv' is the summary's file"
    elif case == "measurement":
        m.write_text(f"program,measurement\n{pocket},{SAMPLES / 'measurements' / 'pocket_hidden.csv'}\n")
        want = "batch optimize takes no measurement"
    elif case == "ledger":
        m.write_text(f"program\n{pocket}\n")
        args += ["--ledger", tmp_path / "tools.db", "--tool-id", "T1=EM1"]
        want = "--ledger names a file that does not travel with a job"
    elif case == "out-file":
        m.write_text(f"program\n{pocket}\n")
        out.write_text("taken")
        want = "a file, not a folder"
    else:
        pytest.importorskip("distributed")
        m.write_text(f"program\n{pocket}\n")
        (tmp_path / "sched.json").write_text("{}")
        args += ["--scheduler-file", tmp_path / "sched.json"]
        want = "no scheduler address in it"
    r = mtwin("batch", "optimize", *args)
    assert r.returncode == 2, r.stderr
    assert want in r.stderr and "Traceback" not in r.stderr
    assert not out.exists() or out.read_text() == "taken"


def test_a_calibrated_twin_file_equals_the_command_alone_at_the_batch_date(tmp_path):
    meas = SAMPLES / "measurements" / "pocket_hidden.csv"
    r = mtwin("batch", "calibrate", SAMPLES / "pocket.nc", "--measurement", meas, "-o", tmp_path / "cal",
              "--workers", "0", "--fit", "spindle-no-load", "--json")
    assert r.returncode == 0, r.stderr
    epoch = json.loads(r.stdout)["summary"]["source_date_epoch"]
    alone = tmp_path / "alone.toml"
    a = mtwin("calibrate", SAMPLES / "pocket.nc", meas, "--fit", "spindle-no-load", "-o", alone,
              env={**os.environ, "SOURCE_DATE_EPOCH": str(epoch)})
    assert a.returncode == 0, a.stderr
    assert (tmp_path / "cal" / "pocket@default" / "twin.toml").read_bytes() == alone.read_bytes()


def test_ctrl_c_stops_the_batch_keeps_the_finished_jobs_and_says_which_did_not_run(tmp_path):
    progs = [SAMPLES / f for f in ("contour.nc", "pocket.nc", "finish_wall.nc", "wear_passes.nc")]
    m = _manifest(tmp_path, progs, TWINS)
    out = tmp_path / "out"
    # (Ctrl-C's default restored in the child: a suite run in the background, `pytest &`, hands
    # its children SIGINT ignored, and Python then installs no KeyboardInterrupt for it)
    batch = subprocess.Popen([sys.executable, "-m", "mtwin", "batch", "optimize", "--manifest", str(m), "-o", str(out),
                              "--workers", "0", "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    t0 = time.time()
    while not list(out.glob("*/result.json")) and time.time() - t0 < 120:
        time.sleep(0.05)
    batch.send_signal(signal.SIGINT)
    stdout, stderr = batch.communicate(timeout=120)
    assert batch.returncode == 130, stderr
    doc = json.loads((out / "summary.json").read_text())
    done = [j for j in doc["jobs"] if j["status"] == "ok"]
    assert doc["summary"]["interrupted"] and doc["summary"]["not run"] >= 1 and done
    assert len(done) + doc["summary"]["not run"] == len(doc["jobs"])  # the job interrupted is not run, not failed
    for j in done:  # the finished jobs' outputs are whole
        assert Path(j["outputs"]["program"]).stat().st_size > 0 and "</html>" in Path(j["outputs"]["report"]).read_text()
    assert "not run (interrupted)" in stderr


def test_a_limit_a_machines_logs_never_reach_is_a_bound_in_the_fleet_table():
    # the arc limit of a machine whose logs run no arc at it is the least they allow: shown "≥",
    # never marked as the machine that differs (its logs cannot tell it from the others')
    from types import SimpleNamespace

    from mtwin.fleet.batch import Batch, parameters_csv
    from mtwin.fleet.job import Outcome

    key = "effects.arc-acceleration.acceleration"
    rec = {"a": ({key: 400.0}, {key: 13.0}, {}), "b": ({key: 405.0}, {key: 14.0}, {}),
           "c": ({key: 530.0}, {key: None}, {key: {"least": 530.0, "fitted": 939.0}})}
    jobs = [SimpleNamespace(name=n) for n in rec]
    b = Batch("calibrate", jobs, {n: Outcome(n, "ok", record={"params": p, "uncertainty": u, "unreached": un})
                                   for n, (p, u, un) in rec.items()})
    (row,) = b.fleet_table()
    c = row["machines"]["c"]
    assert c["at_least"] and not c["odd"] and c["ratio"] == pytest.approx(530 / 405)
    assert not row["machines"]["a"]["at_least"]
    b.rows = lambda: []  # (no held-out figures here)
    csv_rows = parameters_csv(b).splitlines()
    assert csv_rows[0].endswith(",holdout_cycle_error_pct,at_least")
    assert csv_rows[3] == f"c,530,,,{key}" and csv_rows[1] == "a,400,13,,"
