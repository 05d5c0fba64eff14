"""The model-against-measurement loop: synthetic measurements (``synth``) now; compare,
diagnose and calibrate build on them (``docs/effects.md``)."""
