"""A linear modal model of a force-excited structure, fitted to its frequency response.

The baseline for ``ident discover --baseline linear --excitation COL:force``:
a structure with many modes in the band (an aircraft, a frame) is not a
second-order model in its sensor coordinates, so we fit the receptance
(displacement per force) of every response with common poles,

    H_i(s) = sum_r R_ir / (s - p_r) + conj,   sum_r 2 Re R_ir = 0,

by vector fitting (Gustavsen and Semlyen 1999: poles relocated as the zeros
of a weighting function, conjugate pairs kept in a real basis, unstable poles
mirrored). The constraint makes the receptance fall like 1/s^2, so an
accelerometer needs no derivative of the force. The FRF is the H1 estimate
(Welch) on the lines where the force has power.

States x_r obey x_r' = p_r x_r + u_r; response i has displacement
sum 2 Re(R_ir x_r), velocity sum 2 Re(R_ir p_r x_r) and acceleration
sum 2 Re(R_ir p_r x_r'). The force F enters every mode with gain 1 (response 1
is the driving point, collocated with F). A force f at response j enters mode
r with gain R_jr / R_1r (reciprocity: R_ijr = psi_ir psi_jr), which is how an
internal force found by discovery (an interface between responses j and k
pushing +f on j and -f on k) feeds back into the model with physical units.
Time stepping is exact for a piecewise-linear input (first-order hold); the
nonlinear force is evaluated predictor-corrector, so the loop is second order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.signal import csd, welch

from .linear_discovery import _term


@dataclass(frozen=True)
class ModalModel:
    poles: np.ndarray  # (m,) complex, Im > 0, Re < 0
    residues: np.ndarray  # (k, m) complex receptance residues [m/N]

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.abs(self.poles) / (2 * np.pi)

    @property
    def damping_ratios(self) -> np.ndarray:
        return -self.poles.real / np.abs(self.poles)

    def input_gain(self, j: int, k: int | None = None, floor: float = 0.05) -> np.ndarray:
        """Modal input of a unit force at response j (minus one at k, for a force between j and k).

        R_jr / R_1r; a mode whose driving-point residue is below ``floor`` of the largest is left out
        (zero): F hardly excites it, so its R_1r is mostly fitting noise and the ratio explodes."""
        w = self.residues[j] - (self.residues[k] if k is not None else 0.0)
        r1 = self.residues[0]
        ok = np.abs(r1) >= floor * np.abs(r1).max()
        return np.where(ok, w / np.where(ok, r1, 1.0), 0.0)


def frf(u: np.ndarray, Y: np.ndarray, fs: float, nperseg: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H1 estimate of response per input: frequencies, (k, nf) complex FRF, input PSD."""
    f, puu = welch(u, fs, nperseg=nperseg)
    H = np.array([csd(u, Y[:, i], fs, nperseg=nperseg)[1] / np.where(puu > 0, puu, np.inf)
                  for i in range(Y.shape[1])])
    return f, H, puu


def _basis(s: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """(nf, 2m) real-coefficient basis: 1/(s-a) + 1/(s-a*) and j/(s-a) - j/(s-a*) per pair."""
    a = poles[None, :]
    s = s[:, None]
    p1 = 1 / (s - a) + 1 / (s - a.conj())
    p2 = 1j / (s - a) - 1j / (s - a.conj())
    out = np.empty((s.shape[0], 2 * poles.size), complex)
    out[:, 0::2], out[:, 1::2] = p1, p2
    return out


def _stable_pairs(eig: np.ndarray, m: int) -> np.ndarray:
    """m upper-half-plane stable poles from the relocation's eigenvalues (real ones paired up)."""
    cplx = eig[eig.imag > 1e-9 * np.abs(eig).max()]
    real = np.sort(eig[np.abs(eig.imag) <= 1e-9 * np.abs(eig).max()].real)
    extra = [complex(0.5 * (real[i] + real[i + 1]), 0.5 * abs(real[i + 1] - real[i]) + 1e-3)
             for i in range(0, len(real) - 1, 2)]
    poles = np.concatenate([cplx, np.array(extra, complex)])[:m]
    return -np.abs(poles.real) + 1j * np.abs(poles.imag)


def _residues(s: np.ndarray, H: np.ndarray, poles: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Residues (k, m) for fixed poles, weighted (w (k, nf)) least squares with sum_r 2 Re R_r = 0."""
    Phi = _basis(s, poles)
    # eliminate the last pair's real coefficient: c_re[m-1] = -sum of the others
    P = Phi.copy()
    P[:, 0:-2:2] -= Phi[:, [-2]]
    P = np.delete(P, -2, axis=1)
    m = poles.size
    R = np.empty((H.shape[0], m), complex)
    for i in range(H.shape[0]):
        A = P * w[i][:, None]
        b = H[i] * w[i]
        x = np.linalg.lstsq(np.vstack([A.real, A.imag]), np.concatenate([b.real, b.imag]), rcond=None)[0]
        x = np.insert(x, 2 * m - 2, -np.sum(x[0:2 * m - 2:2]))
        R[i] = x[0::2] + 1j * x[1::2]
    return R


def vector_fit(f_hz: np.ndarray, H: np.ndarray, n_modes: int, iterations: int = 20) -> ModalModel:
    """Common-pole rational fit of receptances H (k, nf) at frequencies f_hz (all > 0)."""
    f_hz = np.asarray(f_hz, float)
    s = 2j * np.pi * f_hz
    k, nf = H.shape
    if nf < 4 * n_modes:
        raise ValueError(f"{nf} frequency lines are too few to fit {n_modes} modes")
    # weights: each response counts alike, every line relative to the response's level
    w = np.broadcast_to(1.0 / np.sqrt(np.mean(np.abs(H) ** 2, axis=1, keepdims=True)), H.shape)
    beta = 2 * np.pi * np.linspace(f_hz.min(), f_hz.max(), n_modes)
    poles = -0.01 * beta + 1j * beta
    for _ in range(iterations):
        Phi = _basis(s, poles)
        m2 = 2 * n_modes
        rows, rhs = [], []
        for i in range(k):
            blk = np.zeros((nf, k * m2 + m2), complex)
            blk[:, i * m2:(i + 1) * m2] = Phi * w[i][:, None]
            blk[:, k * m2:] = -(H[i] * w[i])[:, None] * Phi
            rows.append(blk)
            rhs.append(H[i] * w[i])
        A = np.vstack(rows)
        b = np.concatenate(rhs)
        x = np.linalg.lstsq(np.vstack([A.real, A.imag]), np.concatenate([b.real, b.imag]), rcond=None)[0]
        ct = x[k * m2:]
        # zeros of sigma = eig(A - b c~^T) in the real realisation of the pairs
        Ar = np.zeros((m2, m2))
        br = np.zeros(m2)
        for r, a in enumerate(poles):
            Ar[2 * r:2 * r + 2, 2 * r:2 * r + 2] = [[a.real, a.imag], [-a.imag, a.real]]
            br[2 * r] = 2.0
        poles = _stable_pairs(np.linalg.eigvals(Ar - np.outer(br, ct)), n_modes)
        if poles.size < n_modes:  # lost pairs: put them back spread over the band
            add = 2 * np.pi * np.linspace(f_hz.min(), f_hz.max(), n_modes - poles.size + 2)[1:-1]
            poles = np.concatenate([poles, -0.01 * add + 1j * add])
    order = np.argsort(poles.imag)
    poles = poles[order]
    return ModalModel(poles, _residues(s, H, poles, w))


def fit_modal(u: np.ndarray, Y: np.ndarray, fs: float, n_modes: int, nperseg: int | None = None,
              band_share: float = 0.01) -> tuple[ModalModel, np.ndarray]:
    """Fit receptances from force u and accelerations Y; returns the model and the fitted band's
    frequencies (lines where the force has power)."""
    nperseg = nperseg or int(min(len(u) // 4, 2 ** int(np.log2(fs * 20))))
    f, H, puu = frf(u, Y, fs, nperseg)
    keep = (puu > band_share * puu.max()) & (f > 0)
    if keep.sum() < 8:
        raise ValueError("the excitation has power on too few frequency lines to fit a modal model")
    f, H = f[keep], H[:, keep]
    return vector_fit(f, H / -(2 * np.pi * f) ** 2, n_modes), f


@njit(cache=True, nogil=True)
def _foh(p, fs):  # pragma: no cover - compiled
    """x[i+1] = a x[i] + w0 u[i] + w1 u[i+1]: x' = p x + u exact for u linear over a step."""
    dt = 1.0 / fs
    a = np.exp(p * dt)
    w1 = (a - 1 - p * dt) / (p * p * dt)
    return a, (a - 1) / p - w1, w1


@njit(cache=True, nogil=True)
def _simulate(p, R, F, b, wd, code, coef, p1, p2, g_ext, fs, bound):  # pragma: no cover - compiled
    """Accelerations (n, k); modal input u_r = F + b_r f, f = g_ext + term(delta, delta') with
    delta = sum 2 Re(wd_r x_r) (term code 0 adds nothing). NaN after |delta| exceeds ``bound``."""
    n = F.shape[0]
    m = p.shape[0]
    k = R.shape[0]
    a, w0, w1 = _foh(p, fs)
    out = np.full((n, k), np.nan)
    x = np.zeros(m, np.complex128)
    wv = wd * p

    def force(xx, g):
        d = 0.0
        dv = 0.0
        for r in range(m):
            d += 2 * (wd[r] * xx[r]).real
            dv += 2 * (wv[r] * xx[r]).real
        return d, g + _term(code, coef, p1, p2, d, dv)

    f0 = force(x, g_ext[0])[1]
    for i in range(n):
        u0 = F[i] + b * f0
        xdot = p * x + u0
        for j in range(k):
            acc = 0.0
            for r in range(m):
                acc += 2 * (R[j, r] * p[r] * xdot[r]).real
            out[i, j] = acc
        if i == n - 1:
            break
        xp = a * x + w0 * u0 + w1 * (F[i + 1] + b * f0)  # predictor, then the force at its end
        f1 = force(xp, g_ext[i + 1])[1]
        x = a * x + w0 * u0 + w1 * (F[i + 1] + b * f1)
        d0, f0 = force(x, g_ext[i + 1])
        if not abs(d0) <= bound:
            break
    return out


def simulate(model: ModalModel, F: np.ndarray, fs: float, *, b: np.ndarray | None = None,
             wd: np.ndarray | None = None, term: tuple = (0, 0.0, 1.0, 0.0), g_ext: np.ndarray | None = None,
             bound: float = np.inf) -> np.ndarray:
    """Accelerations (n, k) from rest under force F, optionally with an internal force entering with
    modal gains ``b``: a catalogue term (code, coef, p1, p2) on the coordinate with residues ``wd``,
    or a given signal ``g_ext``."""
    m = model.poles.size
    F = np.ascontiguousarray(F, float)
    b = np.zeros(m, complex) if b is None else np.asarray(b, complex)
    wd = np.zeros(m, complex) if wd is None else np.asarray(wd, complex)
    g = np.zeros(len(F)) if g_ext is None else np.ascontiguousarray(g_ext, float)
    code, coef, p1, p2 = term
    return _simulate(model.poles.astype(complex), np.ascontiguousarray(model.residues, complex), F, b, wd,
                     int(code), float(coef), float(max(p1, 1e-12)), float(p2), g, float(fs), float(bound))


@njit(cache=True, nogil=True)
def _state_rates(p, F, b, g, fs):  # pragma: no cover - compiled
    """x_r' (n, m) of x_r' = p_r x_r + F + b_r g from rest, exact for piecewise-linear inputs."""
    n = F.shape[0]
    a, w0, w1 = _foh(p, fs)
    out = np.empty((n, p.shape[0]), np.complex128)
    x = np.zeros(p.shape[0], np.complex128)
    for i in range(n):
        u0 = F[i] + b * g[i]
        out[i] = p * x + u0
        if i < n - 1:
            x = a * x + w0 * u0 + w1 * (F[i + 1] + b * g[i + 1])
    return out


def refit_residues(model: ModalModel, F: np.ndarray, Y: np.ndarray, fs: float, seg: slice,
                   b: np.ndarray | None = None, g: np.ndarray | None = None) -> ModalModel:
    """Residues for the model's poles by least squares on measured accelerations Y (n, k) over ``seg``
    (time domain: the error a simulation makes, which is what discovery scores). A known internal
    force g entering with modal gains b may drive the states besides F."""
    p = model.poles
    b = np.zeros(p.size, complex) if b is None else np.asarray(b, complex)
    g = np.zeros(len(F)) if g is None else np.ascontiguousarray(g, float)
    y = (p * _state_rates(p.astype(complex), np.ascontiguousarray(F, float), b, g, float(fs)))[seg]
    m = p.size
    # acceleration_i = sum_r 2 (Re R Re y_r - Im R Im y_r), with sum_r Re R_r = 0 (eliminate the last)
    X = np.empty((y.shape[0], 2 * m))
    X[:, 0::2], X[:, 1::2] = 2 * y.real, -2 * y.imag
    Xc = np.delete(X - np.where(np.arange(2 * m) % 2 == 0, 1, 0) * X[:, [2 * m - 2]], 2 * m - 2, axis=1)
    R = np.empty((Y.shape[1], m), complex)
    for i in range(Y.shape[1]):
        c = np.linalg.lstsq(Xc, Y[seg, i], rcond=None)[0]
        c = np.insert(c, 2 * m - 2, -np.sum(c[0:2 * m - 2:2]))
        R[i] = c[0::2] + 1j * c[1::2]
    return ModalModel(p, R)


def refine_poles(model: ModalModel, F: np.ndarray, Y: np.ndarray, fs: float, seg: slice,
                 max_nfev: int = 30, stride: int = 2, b: np.ndarray | None = None,
                 g: np.ndarray | None = None) -> ModalModel:
    """Poles by least squares on the simulation error over ``seg`` (residues solved for at every step,
    variable projection). The H1 estimate's window biases damping; the time domain does not."""
    from scipy.optimize import least_squares

    scale = Y[seg].std(axis=0)
    Fc = np.ascontiguousarray(F, float)

    def build(x):
        m = x.size // 2
        return np.exp(x[:m]) * -1 + 1j * np.exp(x[m:])

    def resid(x):
        mm = refit_residues(ModalModel(build(x), model.residues), Fc, Y, fs, seg, b, g)
        sim = simulate(mm, Fc, fs, b=b, g_ext=g)[seg][::stride]
        return ((sim - Y[seg][::stride]) / scale).ravel()

    x0 = np.concatenate([np.log(-model.poles.real), np.log(model.poles.imag)])
    x = least_squares(resid, x0, max_nfev=max_nfev, x_scale=0.01, diff_step=1e-5).x
    return refit_residues(ModalModel(build(x), model.residues), Fc, Y, fs, seg, b, g)
