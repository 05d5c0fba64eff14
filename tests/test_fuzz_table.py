"""A table of bad inputs per command (issue 33, item 7): each ends in exit 2 with an ``error:``
message, no traceback, no numpy warning, and the folder of inputs and outputs unchanged.

The commands run in this process (``mtwin.cli.run_command``, what a batch job runs), so the
table of some 120 cases takes seconds, not the minutes a subprocess per case would."""
from __future__ import annotations

import os
import warnings
from pathlib import Path

import pytest

from mtwin.cli import run_command

ROOT = Path(__file__).resolve().parents[1]
POCKET = ROOT / "samples" / "pocket.nc"
CHATTER_TWIN = ROOT / "samples" / "machines" / "chatter-demo.toml"
GOOD = "(T1 D=6 CR=0 - flat end mill)\nG21 G90 G17\nT1 M6\nS8000 M3\nG0 X-5 Y0 Z5\nG0 Z-1\nG1 X30 F300\nG0 Z5\nM30\n"

# programs a shop could send by mistake, or a hostile one: (name, text, what the message names)
PROGRAMS = {
    "binary": (b"\x00\x01\x02\x03G1 X1\n", "p.nc:1:"),
    "bad_word": (b"G21 G90\nG1 X1 Q F100\n", "p.nc:2:"),
    "unknown_g": (b"G21 G90\nG777 X1\n", "p.nc:2:"),
    "unknown_m": (b"G21 G90\nM777\n", "p.nc:2:"),
    "no_feed": (b"G21 G90\nG1 X10\nM30\n", "p.nc:2:"),
    "repeat_huge": (b"G21 G90\nG0 X0 Y0 Z5\nG91 G81 X0.001 Z-1 R1 L999999999 F100\nM30\n", "repeat count"),
    "m98_repeat_huge": (b"G21\nM98 P100 L99999999\nM30\nO100\nG4 P1\nM99\n", "repeat count"),
    "self_call_g65": (b"O1000\nG65 P2000 A1\nM30\nO2000\nG65 P2000 A[#1+1]\nM99\n", "nested deeper"),
    "self_call_m98": (b"O1\nM98 P1\n", "nesting deeper"),
    "self_call_osub": (b"o100 sub\no100 call\no100 endsub\no100 call\nM2\n", "nested deeper"),
    "while_forever": (b"G21 G90\n#1=0\nWHILE[1 EQ 1]DO1\n#1=#1+1\nEND1\nM30\n", "without a move"),
    "goto_forever": (b"G21 G90\nN10 #1=#1+1\nGOTO10\nM30\n", "without a move"),
    "o_while_forever": (b"G21\n#1=0\no1 while [1]\n#1=[#1+1]\no1 endwhile\nM2\n", "without a move"),
    "unclosed_comment": (b"G21 G90\nG1 X1 (no end F100\n", "p.nc:2:"),
    "div_zero": (b"G21 G90\n#1=[1/0]\nG1 X#1 F100\nM30\n", "p.nc:2:"),
    "arc_bad_radius": (b"G21 G90 G17\nG0 X0 Y0\nG2 X10 Y0 I1 J0 F100\nM30\n", "p.nc:3:"),
    "lathe_in_mill": (b"G21 G90\nG7\nG71 P1 Q2 U0.5 W0.1 D1 F100\nM30\n", "p.nc:"),
    "number_overflow": (b"G21 G90\nG1 X1e999 F100\nM30\n", "p.nc:2:"),
    "nan_word": (b"G21 G90\nG1 Xnan F100\nM30\n", "p.nc:2:"),
    "empty_sub_call": (b"G21\nM98 P9999\nM30\n", "p.nc:2:"),
    "helix_turns_huge": (b"G21 G90 G17\nG0 X0 Y0 Z0\nG2 X0 Y0 Z-10 I5 J0 P99999 F1000\nM30\n", "p.nc:3:"),
    # a peck cycle of 1e8 pecks (R 1e8 mm above, Q 1 mm) ran without end; a macro value past any
    # float was an internal error
    "pecks_huge": (b"G21 G90 G17\nG0 X0 Y0 Z5\nG83 X30. Y25. Z-5. R99999999. Q1. F100.\nG80\nM30\n", "p.nc:3:"),
    "pecks_tiny_q": (b"G21 G90 G17\nG0 X0 Y0 Z5\nG83 X30. Y25. Z-5. R2. Q0.00000001 F100.\nG80\nM30\n", "p.nc:3:"),
    "macro_power_overflow": (b"G21 G90\n#1 = [10 ** 400]\nG1 X#1 F100\nM2\n", "p.nc:2:"),
    "macro_product_overflow": (b"G21 G90\n#1 = [1" + b"*99999999" * 45 + b"]\nG1 X#1 F100\nM2\n", "p.nc:2:"),
}

TWINS = {
    "twin_not_toml": ("this is [not toml\n", "t.toml"),
    "twin_unknown_section": ("[nonsense]\nx = 1\n", "t.toml"),
    "twin_huge_velocity": ("[axes.x]\nmax_velocity = 1e308\n", "max_velocity"),
    "twin_svi": ("[axes.x.servo]\ns_vi = 1e308\n", "s_vi"),
    "twin_negative_mass": ("[axes.x]\nmass = -5\n", "mass"),
    "twin_bad_unit": ('[axes.x]\nmax_velocity = "10 parsecs"\n', "max_velocity"),
    "twin_flutes": ("[tools.1]\ntype = \"flat\"\ndiameter = 6\nflutes = 100000\n", "flutes"),
    "twin_mode_k": ("[tools.1]\ntype = \"flat\"\ndiameter = 6\n[[tools.1.modes]]\ndirection = \"x\"\nfn = 900\n"
                    "zeta = 0.02\nk = 1e-300\n", "stiffness"),
    "twin_mode_zeta": ("[tools.1]\ntype = \"flat\"\ndiameter = 6\n[[tools.1.modes]]\ndirection = \"x\"\nfn = 900\n"
                       "zeta = -0.1\nk = 1e7\n", "zeta"),
    "twin_frf_device": ('[tools.1]\ntype = "flat"\ndiameter = 6\nfrf = "/dev/zero"\n', "frf"),
    "twin_unknown_material": ('[cutting]\nmaterial = "unobtainium"\n', "unobtainium"),
    "twin_servo_period": ("[controller]\nservo_period = 1e-300\n", "servo_period"),
    "twin_bool_number": ("[axes.x]\nmax_velocity = true\n", "max_velocity"),
    # finite, and still no machine's: bounds declared with each parameter
    "twin_bell_time": ("[controller]\nbell_time = 1e5\n", "bell_time"),
    "twin_in_position": ("[controller]\nin_position = 9e5\n", "in_position"),
    "twin_tool_diameter": ('[tools.1]\ntype = "flat"\ndiameter = 9e5\n', "diameter"),
    "twin_tool_helix": ('[tools.1]\ntype = "flat"\ndiameter = 6\nhelix = 9e5\n', "helix"),
    "twin_spindle_loss": ("[cutting]\nspindle_loss = [1e99, 0.0, 0.0]\n", "spindle_loss"),
    "twin_stock_far": ("[cutting]\nstock = [0, 0, -20, 60, 50, 1e99]\n", "stock"),
    "twin_mode_fn_tiny": ("[tools.1]\ntype = \"flat\"\ndiameter = 6\n[[tools.1.modes]]\ndirection = \"x\"\n"
                          "fn = 1e-300\nzeta = 0.02\nk = 1e7\n", "below any tool-tip mode"),
}

MEASUREMENTS = {
    "meas_inf": ("t,line,spindle_power\n0,1,100\n0.1,1,inf\n0.2,1,100\n", "m.csv:3:"),
    "meas_huge_t": ("t,line,spindle_power\n0,1,100\n1e308,1,100\n", "m.csv:3:"),
    # finite, under the format's magnitude cap, and still no machine's: a bound per column's unit
    "meas_t_1e99": ("t,line,spindle_power\n0,1,100\n1e99,1,100\n", "m.csv:3:1:"),
    "meas_power_1e99": ("t,line,spindle_power\n0,1,100\n0.1,1,1e99\n", "m.csv:3:3:"),
    "meas_unit_scaled": ("t,line,x[m]\n0,1,0.1\n0.1,1,1e4\n", "m.csv:3:3:"),
    "meas_summary_1e99": ("first_line,last_line,spindle_power_mean\n40,45,1e99\n", "m.csv:2:3:"),
    "meas_text": ("t,line,spindle_power\n0,1,100\n0.1,1,lots\n", "m.csv:3:"),
    "meas_backwards": ("t,line,spindle_power\n0,1,100\n0.2,1,100\n0.1,1,100\n", "m.csv:4:"),
    "meas_no_header": ("0,1,100\n0.1,1,100\n", "m.csv"),
    "meas_short_row": ("t,line,spindle_power\n0,1,100\n0.1,1\n", "m.csv:3:"),
    "meas_empty": ("", "m.csv"),
    "meas_binary": ("\x00\x00\x00", "m.csv"),
    "meas_field_huge": ("t,line,spindle_power\n0,1,100\n0.1,1," + "9" * 200_000 + "\n", "m.csv:3:"),
}

LOGS = {
    # a feed over 1,000 m/min (the cap was 1,000 times that), an override over the twin's 1,000 %
    "log_feed_16e6_mm_s": ("2024-01-01T00:00:00.000Z|execution|ACTIVE\n2024-01-01T00:00:00.100Z|Feed_Rate|16000000\n",
                           "log.txt:2:"),
    "log_override_huge": ("2024-01-01T00:00:00.000Z|execution|ACTIVE\n2024-01-01T00:00:00.100Z|Feed_Override|999999\n",
                          "log.txt:2:"),
    "log_feed_huge": ("2024-01-01T00:00:00.000Z|execution|ACTIVE\n2024-01-01T00:00:00.100Z|Feed_Rate|1e308\n",
                      "log.txt:2:"),
    "log_block_negative": ("2024-01-01T00:00:00.000Z|execution|ACTIVE\n2024-01-01T00:00:00.100Z|Block_Number|-3\n",
                           "log.txt:2:"),
    "log_block_fraction": ("2024-01-01T00:00:00.000Z|execution|ACTIVE\n2024-01-01T00:00:00.100Z|Block_Number|3.7\n",
                           "log.txt:2:"),
    "log_not_shdr": ("hello world\n", "log.txt"),
    "log_billion_laughs": ('<?xml version="1.0"?><!DOCTYPE l [<!ENTITY a "aaaaaaaaaa">'
                           '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;"><!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">'
                           ']><MTConnectStreams>&c;</MTConnectStreams>', "log.txt"),
}


def _cases():
    out = []
    for name, (text, where) in PROGRAMS.items():
        cmds = (["parse"], ["simulate"], ["optimize", "-o", "{d}/o.nc"], ["scale", "--feed", "1.2", "-o", "{d}/o.nc"],
                ["verify", "{d}/p.nc"])
        if "forever" in name or "pecks" in name:  # (3-5 s each to reach the guard, in the front end every
            cmds = cmds[:1] if name != "while_forever" else cmds[2:3]  # command shares)
        for cmd in cmds:
            out.append(pytest.param({"p.nc": text}, [cmd[0], "{d}/p.nc", *cmd[1:]], where, id=f"{cmd[0]}-{name}"))
    for name, (text, where) in TWINS.items():
        for cmd in (["simulate", "{d}/p.nc"], ["optimize", "{d}/p.nc", "-o", "{d}/o.nc"]):
            out.append(pytest.param({"p.nc": GOOD, "t.toml": text}, [*cmd, "--twin", "{d}/t.toml"], where,
                                    id=f"{cmd[0]}-{name}"))
    for name, (text, where) in MEASUREMENTS.items():
        for cmd in ("compare", "calibrate", "diagnose"):
            extra = ["-o", "{d}/c.toml", "--fit", "spindle-no-load"] if cmd == "calibrate" else []
            out.append(pytest.param({"p.nc": GOOD, "m.csv": text}, [cmd, "{d}/p.nc", "{d}/m.csv", *extra], where,
                                    id=f"{cmd}-{name}"))
    for name, (text, where) in LOGS.items():
        out.append(pytest.param({"log.txt": text}, ["import", "mtconnect", "{d}/log.txt", "-o", "{d}/m.csv"], where,
                                id=f"import-{name}"))
    # impossible parameters, one per option family
    opts = {
        "simulate-every-0": ["simulate", "{d}/p.nc", "--every", "0"],
        "simulate-stock-inverted": ["simulate", "{d}/p.nc", "--stock", "10,10,0,0,0,-5"],
        "simulate-stock-nan": ["simulate", "{d}/p.nc", "--stock", "nan,0,0,1,1,1"],
        "simulate-tool-flutes": ["simulate", "{d}/p.nc", "--tool", "1=flat:6:1000"],
        "simulate-tool-diameter": ["simulate", "{d}/p.nc", "--tool", "1=flat:-6:2"],
        "simulate-material": ["simulate", "{d}/p.nc", "--material", "unobtainium"],
        "simulate-missing": ["simulate", "{d}/missing.nc"],
        "simulate-folder": ["simulate", "{d}"],
        "simulate-device": ["simulate", "/dev/zero"],
        "simulate-output-input": ["simulate", "{d}/p.nc", "-o", "{d}/p.nc"],
        "optimize-force-negative": ["optimize", "{d}/p.nc", "--force-limit", "-5", "-o", "{d}/o.nc"],
        "optimize-force-inf": ["optimize", "{d}/p.nc", "--force-limit", "inf", "-o", "{d}/o.nc"],
        "optimize-feed-range": ["optimize", "{d}/p.nc", "--feed-range", "500,100", "-o", "{d}/o.nc"],
        "optimize-tolerance": ["optimize", "{d}/p.nc", "--tolerance", "-1", "-o", "{d}/o.nc"],
        "optimize-objective": ["optimize", "{d}/p.nc", "--objective", "fastest", "-o", "{d}/o.nc"],
        "optimize-method": ["optimize", "{d}/p.nc", "--method", "magic", "-o", "{d}/o.nc"],
        "optimize-limit-scale": ["optimize", "{d}/p.nc", "--limit-scale", "0", "-o", "{d}/o.nc"],
        "optimize-output-input": ["optimize", "{d}/p.nc", "-o", "{d}/p.nc"],
        "optimize-output-symlink": ["optimize", "{d}/p.nc", "-o", "{d}/link.nc"],
        "optimize-output-folder": ["optimize", "{d}/p.nc", "-o", "{d}/nowhere/o.nc"],
        "scale-feed-zero": ["scale", "{d}/p.nc", "--feed", "0", "-o", "{d}/o.nc"],
        "scale-feed-nan": ["scale", "{d}/p.nc", "--feed", "nan", "-o", "{d}/o.nc"],
        "scale-spindle-negative": ["scale", "{d}/p.nc", "--spindle", "-1", "-o", "{d}/o.nc"],
        "lobes-points": ["lobes", "--twin", str(CHATTER_TWIN), "--points", "100000000"],
        "lobes-steps": ["lobes", "--twin", str(CHATTER_TWIN), "--steps", "1"],
        "lobes-immersion": ["lobes", "--twin", str(CHATTER_TWIN), "--immersion", "3"],
        "lobes-no-modes": ["lobes"],
        "lobes-speed-range": ["lobes", "--twin", str(CHATTER_TWIN), "--speed-range", "9000,100"],
        "synth-noise": ["synth", "{d}/p.nc", "--noise", "-1", "-o", "{d}/s.csv"],
        "synth-output-input": ["synth", "{d}/p.nc", "-o", "{d}/p.nc"],
        "materials-unknown": ["materials", "unobtainium"],
        "grind-missing": ["grind", "{d}/missing.toml"],
        "calibrate-frf-missing": ["calibrate-frf", "{d}/missing.csv"],
        "calibrate-frf-text": ["calibrate-frf", "{d}/m.csv"],
        "batch-manifest-missing": ["batch", "simulate", "--manifest", "{d}/missing.csv", "-o", "{d}/out"],
        "tools-ledger-foreign": ["tools", "--ledger", "{d}/m.csv"],
        "config-show-missing": ["config", "show", "{d}/missing.toml"],
        "simulate-decimate-tiny": ["simulate", "{d}/p.nc", "--decimate", "1e-300"],
        "simulate-every-huge": ["simulate", "{d}/p.nc", "--every", "99999999999999999999"],
        "simulate-effect-file-not-python": ["simulate", "{d}/p.nc", "--effect-file", "{d}/m.csv"],
        "batch-scheduler-file-folder": ["batch", "simulate", "{d}/p.nc", "-o", "{d}/out", "--scheduler-file", "{d}"],
        "optimize-layers": ["optimize", "{d}/p.nc", "--layers", "sometimes", "-o", "{d}/o.nc"],
        "optimize-max-layers": ["optimize", "{d}/p.nc", "--max-layers", "1", "-o", "{d}/o.nc"],
        "verify-by-stock-tol": ["verify", "{d}/p.nc", "{d}/p.nc", "--by-stock", "--tol", "0"],
        # finite and absurd: each option held to what a machine, a tool or a user's memory has
        "simulate-decimate-above-servo": ["simulate", "{d}/p.nc", "-o", "{d}/t.csv", "--decimate", "1e99"],
        "simulate-stock-far": ["simulate", "{d}/p.nc", "--stock=0,0,-20,60,50,1e99"],
        "synth-rate-tiny": ["synth", "{d}/p.nc", "--rate", "1e-99", "-o", "{d}/s.csv"],
        "optimize-force-1e99": ["optimize", "{d}/p.nc", "--force-limit", "1e99", "-o", "{d}/o.nc"],
        "optimize-tolerance-1e99": ["optimize", "{d}/p.nc", "--tolerance", "1e99", "-o", "{d}/o.nc"],
        "optimize-rough-tolerance-1e99": ["optimize", "{d}/p.nc", "--rough-tolerance", "1e99", "-o", "{d}/o.nc"],
        "optimize-min-segment-1e99": ["optimize", "{d}/p.nc", "--min-segment", "1e99", "-o", "{d}/o.nc"],
        "optimize-target-power-1e99": ["optimize", "{d}/p.nc", "--objective", "smooth", "--target-power", "1e99",
                                       "-o", "{d}/o.nc"],
        "optimize-population-huge": ["optimize", "{d}/p.nc", "--method", "ga", "--population", "1000000000",
                                     "-o", "{d}/o.nc"],
        "verify-tol-1e99": ["verify", "{d}/p.nc", "{d}/p.nc", "--tol", "1e99"],
        "scale-spindle-1e9": ["scale", "{d}/p.nc", "--spindle", "1e9", "-o", "{d}/o.nc"],
        "lobes-speed-range-1e99": ["lobes", "--twin", str(CHATTER_TWIN), "--speed-range", "100,1e99"],
        "lobes-feed-direction-1e99": ["lobes", "--twin", str(CHATTER_TWIN), "--feed-direction", "1e99"],
        "grind-cases-huge": ["grind", "design", "--cases", "1000000000000"],
        "tools-vb-limit-1e99": ["tools", "--ledger", "{d}/none.db", "--vb-limit", "1e99"],
        "calibrate-frf-freq-1e99": ["calibrate-frf", "{d}/f.csv"],
    }
    frf = "freq,re_xx,im_xx\n100,1e-7,-1e-8\n200,2e-7,-1e-6\n1e99,1e-7,-1e-8\n"
    for name, args in opts.items():
        out.append(pytest.param({"p.nc": GOOD, "m.csv": "not,an,frf\n1,2,3\n", "f.csv": frf}, args, "", id=name))
    return out


def _snapshot(d: Path) -> dict:
    return {p.relative_to(d).as_posix(): (p.read_bytes() if p.is_file() and not p.is_symlink() else
                                          os.readlink(p) if p.is_symlink() else None)
            for p in sorted(d.rglob("*"))}


@pytest.mark.parametrize("files,args,where", _cases())
def test_a_bad_input_ends_in_exit_2_with_a_message_and_changes_nothing(tmp_path, files, args, where):
    for name, text in files.items():
        (tmp_path / name).write_bytes(text if isinstance(text, bytes) else text.encode())
    (tmp_path / "link.nc").symlink_to(tmp_path / "p.nc")
    before = _snapshot(tmp_path)
    argv = [a.replace("{d}", str(tmp_path)) for a in args]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code, out, err = run_command(argv)
    assert code == 2, (argv, code, err[-2000:])
    assert "Traceback" not in err and "internal error" not in err, err[-2000:]
    assert err.lstrip().startswith("error:") or "\nerror:" in err, err[-2000:]
    assert where in err, (where, err[-2000:])
    numpy_warnings = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    assert not numpy_warnings, [str(w.message) for w in numpy_warnings]
    assert "RuntimeWarning" not in err and "numerical warning inside mtwin" not in err, err[-2000:]
    assert _snapshot(tmp_path) == before


def test_a_numpy_warning_inside_a_command_becomes_one_note():
    import contextlib
    import io

    import numpy as np

    from mtwin.cli.app import reports_errors

    @reports_errors
    def command():
        for _ in range(3):
            np.array([1.0]) / np.array([0.0])  # (a division by zero, three times at one place)
        return 0

    buf = io.StringIO()
    with contextlib.redirect_stderr(buf):
        command()
    out = buf.getvalue()
    assert "RuntimeWarning" not in out
    assert out.count("note: a numerical warning inside mtwin (divide by zero encountered in divide, at "
                     "test_fuzz_table.py:") == 1 and "3 times" in out, out
