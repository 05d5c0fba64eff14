"""Parse benchmark: lex + interpret a generated 200,000-line program; mtwin vs pygcode.

Run: python benchmarks/bench_parse.py [--lines N]
Prints lines/second for both in one run, the numba cache-load/compile time
separately, and how long `mtwin --help` takes.
"""
from __future__ import annotations

import argparse
import math
import subprocess
import sys
import time


def generate(n_lines: int) -> bytes:
    """A realistic mix: short G1 moves, arcs, feed changes, comments, N-numbers."""
    out = ["%", "O2000 (BENCH)", "G21 G90 G17 G94", "T1 M6", "S8000 M3", "G0 X0 Y0 Z5", "G1 Z-1 F600"]
    x = y = 0.0
    i = 0
    while len(out) < n_lines - 2:
        i += 1
        k = i % 10
        if k < 6:
            x = 50 * math.cos(i * 0.013)
            y = 50 * math.sin(i * 0.017)
            out.append(f"N{i}G1X{x:.3f}Y{y:.3f}")
        elif k == 6:
            out.append(f"G1 X{x + 1:.3f} Y{y:.3f} F{500 + i % 400}")
            x += 1
        elif k == 7:
            out.append(f"G2 X{x + 2:.3f} Y{y:.3f} I1. J0.")
            x += 2
        elif k == 8:
            out.append(f"G3 X{x - 2:.3f} Y{y:.3f} R1.")
            x -= 2
        else:
            out.append(f"(pass {i})")
    out += ["M30", "%"]
    return ("\n".join(out) + "\n").encode()


def bench_mtwin(data: bytes, repeat: int = 3) -> float:
    from mtwin.gcode.interpreter import load_program

    best = math.inf
    for _ in range(repeat):
        t = time.perf_counter()
        load_program(data, path="bench.nc")
        best = min(best, time.perf_counter() - t)
    return best


def bench_pygcode(data: bytes, n_lines: int) -> float | None:
    try:
        from pygcode import Line, Machine
    except ImportError:
        return None
    lines = data.decode().splitlines()[:n_lines]
    t = time.perf_counter()
    for text in lines:
        Line(text)
    parse_only = time.perf_counter() - t
    print(f"pygcode parse only   ({n_lines:,} lines): {parse_only:.3f} s -> {n_lines / parse_only:,.0f} lines/s")
    m = Machine()
    t = time.perf_counter()
    for text in lines:
        line = Line(text)
        if line.block.words:
            try:
                m.process_block(line.block)
            except Exception:  # pygcode rejects some blocks; we count its speed, not its verdict
                pass
    return time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--lines", type=int, default=200_000)
    ap.add_argument("--pygcode-lines", type=int, default=20_000)
    args = ap.parse_args()
    data = generate(args.lines)
    n = data.count(b"\n")

    t0 = time.perf_counter()
    from mtwin.gcode.interpreter import load_program

    load_program(b"G1 X1 F1\n", path="warm.nc")
    warm = time.perf_counter() - t0
    t = bench_mtwin(data)
    print(f"program: {n:,} lines, {len(data) / 1e6:.1f} MB")
    print(f"numba import + kernel load/compile (first call): {warm:.2f} s")
    print(f"mtwin   lex+interpret: {t:.3f} s  -> {n / t:,.0f} lines/s")
    tp = bench_pygcode(data, args.pygcode_lines)
    if tp is None:
        print("pygcode not installed (pip install pygcode) - no comparison")
    else:
        rate = args.pygcode_lines / tp
        print(f"pygcode parse+process ({args.pygcode_lines:,} lines): {tp:.3f} s -> {rate:,.0f} lines/s")
        print(f"ratio mtwin/pygcode: {n / t / rate:.1f}x")
    # the same program with one '#' parameter: it goes through the macro executor (Python),
    # which passes literal lines through and evaluates only the words with expressions
    macro = b"#1=1\n" + data
    tm = bench_mtwin(macro, repeat=2)
    print(f"mtwin   macro path (same program + one #1): {tm:.3f} s  -> {n / tm:,.0f} lines/s")
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "mtwin", "--help"], capture_output=True, check=True)
    print(f"`mtwin --help`: {time.perf_counter() - t:.3f} s")


if __name__ == "__main__":
    main()
