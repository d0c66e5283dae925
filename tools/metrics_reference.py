#!/usr/bin/env python3
"""Independent reference values for the pinned metric tests in src/io/metrics.rs.

Not a dependency of verisplat: run once, by hand, to recompute the pinned numbers.
    python3 -m venv /tmp/metricsenv
    /tmp/metricsenv/bin/pip install numpy scipy flip-evaluator
    /tmp/metricsenv/bin/python tools/metrics_reference.py

SSIM is the original 3DGS utils/loss_utils.py ssim written with SciPy (11x11 Gaussian,
sigma 1.5, zero padding to the same size, C1 = 0.01^2, C2 = 0.03^2, mean over pixels and
channels), in float64. FLIP is NVIDIA's own implementation (the flip-evaluator package,
LDR, its default 67.02 pixels per degree and an explicit 67.0).
"""
import numpy as np
from scipy.signal import correlate2d
import flip_evaluator

W, H = 48, 40
x = np.arange(W)[None, :, None]
y = np.arange(H)[:, None, None]
c = np.arange(3)[None, None, :]
f32 = np.float32

# The same integer formulas as the Rust test, divided in float32.
pattern = ((x * 7 + y * 13 + c * 29) % 31).astype(f32) / f32(30)
offset = np.clip(pattern + f32(0.1), f32(0), f32(1)).astype(f32)
other = ((x * 3 + y * 5 + c * 11) % 17).astype(f32) / f32(16)
checker = np.where(((x // 4 + y // 4) % 2 + 0 * c) == 1, f32(0.8), f32(0.2)).astype(f32)
shifted = np.where((((x + 1) // 4 + y // 4) % 2 + 0 * c) == 1, f32(0.8), f32(0.2)).astype(f32)
gradient = ((x + 2 * y + c).astype(f32) / f32(W + 2 * H + 2)).astype(f32)
inverse = (f32(1) - gradient).astype(f32)


def ssim(a, b):
    g = np.exp(-((np.arange(11) - 5) ** 2) / (2 * 1.5**2))
    g /= g.sum()
    w = np.outer(g, g)
    a = a.astype(np.float64)
    b = b.astype(np.float64)
    total = 0.0
    for ch in range(a.shape[2]):
        f = lambda p: correlate2d(p, w, mode="same", boundary="fill", fillvalue=0)
        x1, x2 = a[:, :, ch], b[:, :, ch]
        m1, m2 = f(x1), f(x2)
        s11 = f(x1 * x1) - m1 * m1
        s22 = f(x2 * x2) - m2 * m2
        s12 = f(x1 * x2) - m1 * m2
        c1, c2 = 0.01**2, 0.03**2
        m = ((2 * m1 * m2 + c1) * (2 * s12 + c2)) / ((m1 * m1 + m2 * m2 + c1) * (s11 + s22 + c2))
        total += m.mean()
    return total / a.shape[2]


pairs = [
    ("pattern/offset", pattern, offset),
    ("pattern/other", pattern, other),
    ("checker/shifted", checker, shifted),
    ("gradient/inverse", gradient, inverse),
]
for name, a, b in pairs:
    _, flip_default, params = flip_evaluator.evaluate(a, b, "LDR", applyMagma=False)
    _, flip67, _ = flip_evaluator.evaluate(a, b, "LDR", applyMagma=False, parameters={"ppd": 67.0})
    print(f"{name}: ssim {ssim(a, b):.9f} flip(default ppd {params['ppd']:.6f}) {flip_default:.7f} flip(67.0) {flip67:.7f}")
