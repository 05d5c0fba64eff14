"""``mtwin optimize``: segment the predicted power curve, choose F (and S) per segment under
load, power and machine limits, write the program back and prove it (see docs/optimize.md)."""
