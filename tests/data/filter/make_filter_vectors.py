#!/usr/bin/env python3
"""Reference output of SciPy's zero-phase Butterworth low-pass, for crates/core/src/metrics tests.

Run once (needs numpy and scipy) from the repository root:

    python3 tests/data/filter/make_filter_vectors.py

It writes tests/data/filter/butter5_1p25hz.csv with the input signal `x` and the output of

    sosfiltfilt(butter(5, 1.25, fs=FS, output="sos"), x)      # SciPy's default padding

for FS = 100 Hz (the paper's rate) and FS = 10 Hz (same cut-off, other rate). Numbers are written
with Python's repr (shortest round-trip), so Rust parses exactly what SciPy computed. The input is
1000 samples: an offset, a step of +20 at sample 300, a 0.7 Hz sine of amplitude 3 and a
deterministic pseudo-noise from an integer linear congruential generator (exact in any language).
"""
import pathlib

import numpy as np
import scipy
from scipy.signal import butter, sosfiltfilt

N = 1000
k = np.arange(N)
t = k / 100.0
state, noise = 12345, []
for _ in range(N):
    state = (1103515245 * state + 12345) % 2**31
    noise.append(state / 2**31 - 0.5)
x = 40.0 + 20.0 * (k >= 300) + 3.0 * np.sin(2 * np.pi * 0.7 * t) + 1.0 * np.array(noise)

ys = {fs: sosfiltfilt(butter(5, 1.25, fs=fs, output="sos"), x) for fs in (100.0, 10.0)}

out = pathlib.Path(__file__).with_name("butter5_1p25hz.csv")
with out.open("w") as f:
    f.write("x,y_fs100,y_fs10\n")
    for i in range(N):
        f.write(f"{float(x[i])!r},{float(ys[100.0][i])!r},{float(ys[10.0][i])!r}\n")
print(f"wrote {out} with scipy {scipy.__version__}, numpy {np.__version__}")
