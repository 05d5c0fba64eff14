"""Slow, obviously correct implementations the kernels are held against (issue 36).

Each is written from the published rule, not from the kernel: plain Python, no numba, no
shortcuts — fast enough for short inputs only.  ``tests/test_reference.py`` runs the kernels
and these side by side on random and real inputs."""
