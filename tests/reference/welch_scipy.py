#!/usr/bin/env python3
"""Generate scipy reference values for tests/welch_scipy.rs.

Run from anywhere:
    python tests/reference/welch_scipy.py   (the venv `make test` makes has numpy and scipy)
Writes tests/reference/welch_scipy.json next to this script.

Inputs are deterministic: numpy default_rng(20240611) white noise x (4096
samples, fs = 200 Hz); y = x filtered by a bilinear-transformed SDOF base
transmissibility (fn = 12 Hz, zeta = 5 %) plus 10 % independent noise.

Cases (scipy.signal.csd / welch / coherence, scaling='density',
average='mean', return_onesided=True):
  a) window='hann' (periodic), nperseg=512, noverlap=256, detrend='constant'
  b) MATLAB tfestimate defaults: symmetric hamming(L) with L = floor(N/4.5),
     noverlap = floor(L/2), nfft = max(256, 2^nextpow2(L)), detrend=False
  c) window='boxcar', nperseg=256, noverlap=128, nfft=1000 (> nperseg),
     detrend='linear'
  d) window='hamming' (periodic), nperseg=300, noverlap=100, nfft=601 (odd,
     exercises the odd-nfft one-sided doubling), detrend='constant'
"""
import json
import math
import os

import numpy as np
import scipy
import scipy.signal as sig

FS = 200.0
N = 4096
rng = np.random.default_rng(20240611)
x = rng.standard_normal(N)
noise = rng.standard_normal(N)

# SDOF absolute-acceleration transmissibility H(s) = (2 z w s + w^2)/(s^2 + 2 z w s + w^2)
wn = 2 * math.pi * 12.0
zeta = 0.05
b, a = sig.bilinear([2 * zeta * wn, wn**2], [1.0, 2 * zeta * wn, wn**2], fs=FS)
y = sig.lfilter(b, a, x) + 0.1 * noise


def matlab_default(n):
    L = n * 2 // 9  # floor(n / 4.5)
    nov = L // 2
    nfft = max(256, 1 << (L - 1).bit_length())
    return L, nov, nfft


Lm, novm, nfftm = matlab_default(N)
cases = [
    dict(name="a_hann_const", window="hann", nperseg=512, noverlap=256, nfft=512, detrend="constant"),
    dict(name="b_matlab_default", window="hamming_symmetric", nperseg=Lm, noverlap=novm, nfft=nfftm, detrend="none"),
    dict(name="c_boxcar_linear_padded", window="boxcar", nperseg=256, noverlap=128, nfft=1000, detrend="linear"),
    dict(name="d_hamming_odd_nfft", window="hamming", nperseg=300, noverlap=100, nfft=601, detrend="constant"),
]


def scipy_window(name, L):
    if name == "hamming_symmetric":
        return sig.windows.hamming(L, sym=True)
    return name  # scipy's get_window(name, L) -> periodic ("fftbins=True")


out_cases = []
for c in cases:
    kw = dict(
        fs=FS,
        window=scipy_window(c["window"], c["nperseg"]),
        nperseg=c["nperseg"],
        noverlap=c["noverlap"],
        nfft=c["nfft"],
        detrend=False if c["detrend"] == "none" else c["detrend"],
        return_onesided=True,
        scaling="density",
        average="mean",
    )
    f, pxx = sig.welch(x, **kw)
    _, pyy = sig.welch(y, **kw)
    _, pxy = sig.csd(x, y, **kw)
    _, pyx = sig.csd(y, x, **kw)
    ckw = {k: v for k, v in kw.items() if k not in ("return_onesided", "scaling", "average")}
    _, coh = sig.coherence(x, y, **ckw)
    h1 = pxy / pxx
    h2 = pyy / pyx
    r = dict(c)
    r.update(
        freqs=f.tolist(),
        pxx=pxx.tolist(),
        pyy=pyy.tolist(),
        pxy_re=pxy.real.tolist(),
        pxy_im=pxy.imag.tolist(),
        h1_re=h1.real.tolist(),
        h1_im=h1.imag.tolist(),
        h2_re=h2.real.tolist(),
        h2_im=h2.imag.tolist(),
        coherence=coh.tolist(),
    )
    out_cases.append(r)

doc = dict(
    generator="tests/reference/welch_scipy.py",
    numpy=np.__version__,
    scipy=scipy.__version__,
    fs=FS,
    x=x.tolist(),
    y=y.tolist(),
    cases=out_cases,
)
path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "welch_scipy.json")
with open(path, "w") as fh:
    json.dump(doc, fh, separators=(",", ":"))
print(f"wrote {path}: {os.path.getsize(path)} bytes; matlab default L={Lm} noverlap={novm} nfft={nfftm}")
