"""The model-against-measurement loop: synthetic measurements (``synth``), reading
measurements and control logs (``measurement``, ``mtconnect``, ``asrun``), comparing
(``compare``, ``blocks``), diagnosing and calibrating (``fit``, ``timing``) and the twin
file's journal (``journal``); see ``docs/effects.md`` and ``docs/tutorial.md``."""
