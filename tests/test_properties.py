"""Property tests: random programs, random F/S changes and splits always verify; garbage never crashes."""
import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from mtwin.errors import MtwinError
from mtwin.gcode.interpreter import InterpreterSettings, load_program
from mtwin.gcode.records import ARC_CCW, ARC_CW, LINEAR, in_common_frame, machine_xyz, move_lengths
from mtwin.gcode.verify import compare
from mtwin.gcode.writer import Split, rewrite

coord = st.integers(-5000, 5000).map(lambda v: v / 100.0)


@st.composite
def programs(draw):
    lines = [draw(st.sampled_from(["G21 G90 G17", "G20 G90 G17"])), "S5000 M3", "G0 X0 Y0 Z1", "G1 Z-1 F300"]
    x, y = 0.0, 0.0
    inc = False
    for _ in range(draw(st.integers(1, 12))):
        kind = draw(st.sampled_from(["G1", "G2", "G3", "G0", "G91", "G90", "F"]))
        if kind == "G91":
            lines.append("G91")
            inc = True
        elif kind == "G90":
            lines.append("G90")
            inc = False
        elif kind == "F":
            lines.append(f"F{draw(st.integers(10, 3000))}")
        elif kind in ("G0", "G1"):
            nx, ny = draw(coord), draw(coord)
            if inc:
                lines.append(f"{kind} X{nx - x:.2f} Y{ny - y:.2f}")
            else:
                lines.append(f"{kind} X{nx:.2f} Y{ny:.2f}")
            x, y = (float(f"{nx:.2f}"), float(f"{ny:.2f}"))
        else:
            # an arc through a centre offset; end on the same circle
            i, j = draw(coord), draw(coord)
            if abs(i) + abs(j) < 0.5:
                continue
            ang = draw(st.floats(0.1, 6.2))
            cx, cy = x + i, y + j
            r = np.hypot(i, j)
            a0 = np.arctan2(-j, -i)
            nx, ny = round(cx + r * np.cos(a0 + ang), 2), round(cy + r * np.sin(a0 + ang), 2)
            if abs(np.hypot(nx - cx, ny - cy) - r) > 0.001 or np.hypot(nx - x, ny - y) < 0.05:
                continue
            ex, ey = (nx - x, ny - y) if inc else (nx, ny)
            lines.append(f"{kind} X{ex:.2f} Y{ey:.2f} I{i:.2f} J{j:.2f}")
            x, y = nx, ny
    lines.append("M30")
    return ("\n".join(lines) + "\n").encode()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(programs(), st.data())
def test_random_feeds_and_splits_verify(src, data):
    prog = load_program(src, path="rand.nc")
    rec = prog.records
    feed_idx = np.flatnonzero(np.isin(rec["kind"], [LINEAR, ARC_CW, ARC_CCW]))
    # one feed per line (a line runs one move here), random subset changed
    feeds = np.full(rec.size, np.nan)
    splits = {}
    for i in feed_idx:
        if data.draw(st.booleans()):
            feeds[i] = data.draw(st.integers(20, 5000))
        if data.draw(st.booleans()) and i > 1 and move_lengths(rec[i:i + 1])[0] > 0.01:
            n = data.draw(st.integers(1, 3))
            ts = sorted(set(data.draw(st.lists(st.floats(0.05, 0.95), min_size=n, max_size=n))))
            if move_lengths(rec[i:i + 1])[0] * min(np.diff([0.0] + ts + [1.0])) < 0.01:
                continue  # the writer refuses pieces under 0.01 mm (tested apart)
            splits[i] = Split(ts, [data.draw(st.integers(20, 5000)) for _ in range(len(ts) + 1)])
    spindles = np.full(rec.size, np.nan)
    if data.draw(st.booleans()):
        spindles[:] = data.draw(st.integers(1000, 20000))
    out = rewrite(prog, feeds, spindles, splits)  # raises if its own proof fails
    new = load_program(out, path="rand.nc")
    assert compare(prog, new, tol=1e-3) is None


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=300))
def test_garbage_never_crashes(data):
    try:
        load_program(data, path="junk.nc")
    except MtwinError as exc:
        assert str(exc)


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet="GXYZIJKRFSMTPQLNABCW@^0123456789.- ,()%;/\n#[]", max_size=200), st.booleans())
def test_gcode_like_text_never_crashes(text, lenient):
    try:
        prog = load_program(text.encode(), InterpreterSettings(lenient=lenient), path="junk.ngc")
    except MtwinError as exc:
        assert str(exc)
        return
    assert np.isfinite(prog.records["x"]).all()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(programs(), coord, coord, st.integers(-180, 180), coord, coord)
def test_rotated_frames_are_rigid_motions(src, ox, oy, rot, gx, gy):
    """The same program in a frame moved by G10 L2 X Y R and G92: every machine point is the
    rigid motion Rot(R)·(p + G92) + (X, Y) of the program point, and the twin's common frame
    gives back the program's own points."""
    head, _, body = src.partition(b"\n")
    # at the start the tool is at 0,0: G92 X-gx makes the offset +gx; then the frame moves
    moved = head + f"\nG92 X{-gx:.2f} Y{-gy:.2f}\nG10 L2 P1 X{ox:.2f} Y{oy:.2f} R{rot}\nG54\n".encode() + body
    a = load_program(src, InterpreterSettings(dialect="linuxcnc"), path="a.ngc").records
    b = load_program(moved, InterpreterSettings(dialect="linuxcnc"), path="b.ngc").records
    assert len(a) == len(b)
    inch = 25.4 if head.startswith(b"G20") else 1.0
    c, s_ = np.cos(np.radians(rot)), np.sin(np.radians(rot))
    # the machine sees Rot·(p + G92 offset) + G54 offset
    px = a["x"] + gx * inch
    py = a["y"] + gy * inch
    want = np.stack([ox * inch + c * px - s_ * py, oy * inch + s_ * px + c * py, a["z"]], 1)
    np.testing.assert_allclose(machine_xyz(b), want, atol=1e-9)
    np.testing.assert_allclose(b["x"], a["x"], atol=1e-9)
    np.testing.assert_allclose(b["y"], a["y"], atol=1e-9)
    common = in_common_frame(b)
    np.testing.assert_allclose(common["x"], b["x"], atol=1e-9)
