#!/usr/bin/env bash
# Make samples/machines/hurco-vmx24.toml: a Hurco VMX24's timing calibrated with mtwin calibrate
# on the NIST smart-manufacturing test bed's MTConnect logs of plates 12, 13 and 14.
#
#   bash scripts/hurco-vmx24.sh [REALDATA]      (REALDATA: ../shared/realdata by default)
#
# Each step adds the effect `mtwin diagnose` ranks next (the journal shows the error falling
# with each), refitting what came before; the last step fits the axes' base parameters.
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
data="${1:-$here/../shared/realdata}/nist_smstestbed_mtc_hurco"
out="$here/samples/machines/hurco-vmx24.toml"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
runs=()
for p in 12 13 14; do
  runs+=("$data/NC-Code/NIST_MTC_CRADA_PLATE-$p.NC" "$data/Split/Plate-Op1-Hurco04-${p}of20.txt")
done

cat > "$work/0.toml" <<'TOML'
# Hurco VMX24 (NIST smart-manufacturing test bed, machine "Hurco04"): timing calibrated on the
# MTConnect logs of plates 12, 13 and 14 (Plate-Op1-Hurco04-NNof20.txt) with mtwin calibrate.
# Made by: bash scripts/hurco-vmx24.sh   (the journal below is each step's error; see
# docs/validation.md for what it predicts).
#
# Set by hand before calibrating (not fitted):
#   spindle.max_speed 12,000 rpm: the programs' S12000 runs at 12,000 (the log's Spindle_Speed);
#   travel +-1,000 mm: the programs' work offsets (G54/G58) are not fully known, so no travel check;
#   axes.z.max_velocity = X's and Y's rapid rate: the logs hold no Z rapid of known length to
#     read it from (the retracts' length below is derived from it).
#   work offset G54 Z -411 mm (X, Y unknown: 0): the G28 Z retracts run 2.3-2.8 s (2.5 s on
#     average) at the logged rapid rate of 176 mm/s, the first approach after a tool change
#     ~2.0 s beyond its spindle wait: ~400 mm from Z home to the part, so that these moves
#     have their length (with no offset they have none, and the tool-change time took them up);
#   work offset G58 (-133.4, -295.1, 0) mm: the park move at the program's end (G90 G58 X12 Y20)
#     runs 1.6-1.8 s on the log, ~270 mm at the rapid rate; with G58 at 0 it would be 596 mm.
#     Only that length is known: the offset puts the park position along the programmed
#     direction at that distance;
#   spindle.wait_for_stop false: after M5 the Hurco starts the G28 retract at once, while the
#     logged Spindle_Speed still falls, and stands at the M01 before the next tool change for
#     the rest of the braking (0.2 s from S3750, 2.1-2.5 s from S9000, 5.2-5.5 s from S12000);
#     at the program's end it parks while the spindle brakes and completes the program once
#     the spindle is down (3.9 s after M30 from S12000, 0.7 s from S9000);
#   spindle.runup_overlap true: it rapids to X/Y on the block that starts the spindle
#     (G0 X Y S M3) and stands at the next block (Z.25 M8) for the rest of the run-up before
#     the Z approach (none after S750-S5000, 2.0-2.6 s after S9000, 5.1-5.6 s after S12000);
#   controller.in_position 0.2 mm: the logs show no standstill at the rapids' ends (each
#     retract-reposition-approach, timed report to report, is within 0.03 s of the log on average
#     without one); a narrow width, fitted, made the twin wait ~50 ms after every rapid;
#   controller.stop_angle 120 degrees: the plates' zig-zag passes turn by 150-170 degrees and
#     lose a near constant 0.09 s per turn from F508 to F1016 mm/min, as a full stop does (an
#     allowable velocity change per axis carries speed through and loses 0.03-0.07 s, growing
#     with the feed); their other corners turn by 90-100 degrees, none by 100-150.
# Everything else below the [spindle] table comes from the calibration steps:
#   1 spindle-runup (its run-up and braking rates -- the control stands longer after M5 than
#   after M3 at the same speed -- and the speed above which both fall as 1/n: plate 12 runs
#   S12000, 13 and 14 S750-S9000), 2 toolchange-time, 3 rapid-acceleration, 4 arc-acceleration,
#   5 spiral-acceleration (arcs whose I/J words, rounded to 0.0001 in, leave the end point off the
#   circle: the control runs them slower than true circles, and each block takes longer by its
#   v^2/r over a jerk -- 4.8-5.6 ms per half circle at ~190 mm/s^2 on plate 12's helices, below
#   both limits -- which spirals below the limit show on every plate)
#   (the order mtwin diagnose ranks them on the default twin), 6 block-time (what diagnose ranks
#   next on the twin with those five: ~30 ms a block at the least, the control's block rate, seen
#   on the plates' tessellated small circles of 0.3-0.5-mm lines), 7 feed-rapid-wait (where a
#   straight feed line ends and a rapid follows, the machine stands 50-75 ms longer than the twin
#   on every plate, where a feed line follows it does not: an in-position check for cutting
#   feed; and, its rapid_feed, where a rapid ends and a cutting move follows: the approach before
#   every plunge ran 41-55 ms longer on the machine, an in-position check before cutting --
#   without it Y's acceleration came out at twice X's; docs/validation.md), 8 the axes: rapid
#   rates (read off the logged rapids), feed accelerations, jerk (controller.bell_time).
# The servos keep the default machine's velocity feed-forward: fitted without it (0), the
# in-position waits after every rapid take ~70 ms the log does not show, and the fit buys them
# back with unphysical values (Y accelerating 4x X, no arc limit at all).
# Overrides were not logged: 100 % is assumed.  Units: mm, s (the programs are inch).
TOML
cat >> "$work/0.toml" <<'TOML'

[work_offsets]
G54 = [0.0, 0.0, -411.0]
G58 = [-133.4, -295.1, 0.0]

[spindle]
max_speed = 12000.0
wait_for_stop = false
runup_overlap = true

[axes.x]
min_travel = -1000.0
max_travel = 1000.0

[axes.y]
min_travel = -1000.0
max_travel = 1000.0

[axes.z]
min_travel = -1000.0
max_travel = 1000.0
max_velocity = 10560.0

[controller]
in_position = 0.2
stop_angle = 120.0
TOML

cal() { mtwin calibrate "${runs[@]}" --objective timing "$@"; }
cal --twin "$work/0.toml" -o "$work/1.toml" --fit spindle-runup
cal --twin "$work/1.toml" -o "$work/2.toml" --fit toolchange-time --refit
cal --twin "$work/2.toml" -o "$work/3.toml" --fit rapid-acceleration --refit
cal --twin "$work/3.toml" -o "$work/4.toml" --fit arc-acceleration --refit
cal --twin "$work/4.toml" -o "$work/5.toml" --fit spiral-acceleration --refit
cal --twin "$work/5.toml" -o "$work/6.toml" --fit block-time --refit
cal --twin "$work/6.toml" -o "$work/7.toml" --fit feed-rapid-wait --refit
cal --twin "$work/7.toml" -o "$work/8.toml" --refit \
    --param axes.x.max_velocity --param axes.y.max_velocity \
    --param axes.x.max_acceleration --param axes.y.max_acceleration --param axes.z.max_acceleration \
    --param controller.bell_time
cp "$work/8.toml" "$out"
mtwin journal "$out"
