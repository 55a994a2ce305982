"""One-mode oscillators integrated apart from ``ident`` (RK4 in plain Python, or scipy's lsim for a linear one),
so that the data the tests judge discovery on are not the method's own."""

import numpy as np
from scipy.signal import butter, lfilter, lsim


def rk4(u: np.ndarray, fs: float, acc) -> tuple[np.ndarray, np.ndarray]:
    """x and v of x'' = acc(x, x', f) from rest under the force series u (linearly interpolated between
    samples), one RK4 step per sample."""
    h, x, v = 1 / fs, 0.0, 0.0
    xs, vs = np.empty(u.size), np.empty(u.size)
    f = u.tolist() + [float(u[-1])]
    for i in range(u.size):
        fa, fb = f[i], f[i + 1]
        fm = 0.5 * (fa + fb)
        k1x, k1v = v, acc(x, v, fa)
        k2x, k2v = v + 0.5 * h * k1v, acc(x + 0.5 * h * k1x, v + 0.5 * h * k1v, fm)
        k3x, k3v = v + 0.5 * h * k2v, acc(x + 0.5 * h * k2x, v + 0.5 * h * k2v, fm)
        k4x, k4v = v + h * k3v, acc(x + h * k3x, v + h * k3v, fb)
        x += h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
        v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        xs[i], vs[i] = x, v
    return xs, vs


def linear_under_random_force(seed: int, seconds: float = 30.0, fs: float = 1000.0, hz: float = 15.0,
                              zeta: float = 0.02, noise: float = 0.01) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """t, f, x of a one-mode oscillator (``hz``, ``zeta``) under a random force low-passed at 60 Hz (order-4
    Butterworth), integrated by scipy (lsim), its displacement with ``noise`` x its RMS of white noise."""
    t = np.arange(0, seconds, 1 / fs)
    w = 2 * np.pi * hz
    rng = np.random.default_rng(seed)
    f = lfilter(*butter(4, 60 / (fs / 2)), rng.standard_normal(t.size))
    _, x, _ = lsim(([1.0], [1.0, 2 * zeta * w, w * w]), f, t)
    return t, f, x + noise * x.std() * rng.standard_normal(x.size)


def two_masses_pushed(f: np.ndarray, fs: float, rng: np.random.Generator, noise: float = 0.01) -> np.ndarray:
    """(n, 2) accelerations of two unit masses in a chain (springs 800 and 3000 N/m: modes 3.1 and 12.8 Hz,
    stiffness-proportional damping 0.8 and 3.2 %), the first pushed by the force series ``f``, integrated by
    scipy (lsim) from rest, each with ``noise`` x its RMS of white noise."""
    t = np.arange(f.size) / fs
    k1, k2 = 800.0, 3000.0
    K = np.array([[k1 + k2, -k2], [-k2, k2]])
    C = 0.04 / np.sqrt(np.linalg.eigvalsh(K)).mean() * K
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-K, -C]])
    _, y, _ = lsim((A, np.array([[0.0], [0.0], [1.0], [0.0]]), np.hstack([-K, -C]), np.array([[1.0], [0.0]])), f, t)
    return y + noise * y.std(axis=0) * rng.standard_normal(y.shape)
