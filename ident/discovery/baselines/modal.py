"""A modal model fitted to the data: the baseline when no physical model is given.

Receptances of every response's displacement (relative to the frame when the frame is shaken) per
excitation, with common poles:

    z_i(s) = sum_r [ C_ir / (s - lambda_r) + conj ] U(s)

Poles start from vector fitting of the measured frequency response (Gustavsen & Semlyen 1999: poles
relocated as the zeros of a weighting function) and are then refined on the simulation error in the
time domain, the residues C solved by linear least squares inside (variable projection, Golub & Pereyra
1973): the Hann-windowed H1 estimate biases damping, the time domain does not. The order is the lowest
after which two more modes no longer cut that error by 10 %. Every response is compared in its own kind
(displacement, velocity, acceleration), each with its own initial modal state (free response) so a
record need not start at rest.

A force at a location enters mode r with gain lz_r / C_dr when the driving point d is known
(reciprocity; the coefficient then has the force's units) and otherwise with lz_r 2 i omega_r kappa_r,
kappa_r = 1 / b_r^2 unknown per mode (b_r the excitation's participation in mode r; real for real modes,
complex under a voltage-driven shaker), so the search fits one coefficient per mode. Either way the
coefficient per unit modal mass at the location is theta_r (lz_r 2 i omega_r)^2 kappa_r.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from scipy.optimize import least_squares

from ..model import NUMERIC_FAILURES, Element, LeastSquares, LinearModel, mode_states, without_feedthrough
from ..signals import ORDER, Prepared, convert, frf, miso_frf
from ..split import rows_of
from . import Baseline, Location, dominant_mode, element_force

MAX_MODES = 12
BASIS_MODES = 3  # modes per location whose gains the search fits separately (no driving point)
RESOLVED = 1.0  # decay rate times record length below which a pole is a sinusoid, not a mode


def _design(poles, states, drive, t, order: int, starts=(), initial: bool = True) -> np.ndarray:
    """Real design matrix (n, 4m + 2m len(starts), 2m fewer without ``initial``) of one output of
    kinematic ``order``: columns for Re C, Im C (forced response, with the feedthrough of the modal input
    ``drive`` (n, m)), for the free response of the record's initial state (unless not ``initial``: a
    record that starts at rest has none), and for the free response from each of ``starts`` (s) on: an
    unmeasured blow leaves the structure with a modal state nobody measured, which decays like any."""
    lam = poles[None, :]
    forced = lam**order * states
    if order >= 1:
        forced = forced + lam ** (order - 1) * drive
    cols = [2 * forced.real, -2 * forced.imag]
    for t0 in ((0.0,) if initial else ()) + tuple(starts):
        since = t[:, None] - t0
        free = np.where(since >= 0, lam**order * np.exp(lam * np.maximum(since, 0.0)), 0.0)
        cols += [2 * free.real, -2 * free.imag]
    return np.hstack(cols)


def _starts(prep: Prepared) -> tuple[float, ...]:
    return tuple(b / prep.fs_hz for b in prep.blows)


class Columns:
    """The design matrices (``_design``) of one fit over fixed ``rows``, each mode's columns computed
    alone and, with ``keep``, kept for the last ``keep`` poles seen. A finite-difference Jacobian moves
    one pole's decay or frequency per evaluation, so every other mode's columns are those already made at
    the point it is taken at: the pole refinements' least squares spent most of their time rebuilding
    them (independent seed 5: ``_design`` and ``mode_states`` 47 of 150 s). The assembled matrices are
    bitwise those of ``_design`` on all modes at once.

    ``drives``: per block of columns, the modal input's signal (n,) and the element forces acting with it,
    each (force (n,), modal gains (m,)); the first block holds the free responses too (of the record's
    initial state and from each of ``starts`` on), the others only the forced response (the extra inputs
    of ``fit_with_forces``)."""

    def __init__(self, prep: Prepared, rows: np.ndarray, drives, starts=(), keep: int = 0, at_rest: bool = False):
        self.rows, self.t, self.dt = rows, rows / prep.fs_hz, 1.0 / prep.fs_hz
        # with ``at_rest``, of a record that starts at rest (``Prepared.rest_until``): the first signal's
        # band-pass before the record drives the modes, and no initial state is fitted
        self.at_rest = prep.u_at_rest if at_rest else None
        self.initial = self.at_rest is None
        self.orders = sorted({ORDER[k] for k in prep.kinds})
        # each signal and force as given (a drive subtracts a real force times a complex gain) and complex
        self.drives = [(np.asarray(x, complex), [(np.asarray(g), np.asarray(g, complex), np.asarray(gain))
                                                 for g, gain in forces]) for x, forces in drives]
        self.starts, self.keep = tuple(starts), keep
        self.kept: OrderedDict = OrderedDict()

    def _mode(self, r: int, lam: complex) -> dict[int, np.ndarray]:
        """Mode r's columns (len(rows), blocks) per kinematic order, for its pole ``lam``."""
        key = (r, lam)
        if key in self.kept:
            self.kept.move_to_end(key)
            return self.kept[key]
        one, rows = np.array([lam]), self.rows
        pieces: dict[int, list] = {o: [] for o in self.orders}
        for j, (x, forces) in enumerate(self.drives):
            # the states are linear in the drive: the signal's part from rest, then each force's through its gain
            states = np.zeros((rows.size, 1), complex)
            if j == 0 and self.at_rest is not None:  # the excitation, with its band-pass before the record
                lead = self.at_rest.size - x.size
                states += mode_states(one, self.at_rest.astype(complex), self.dt)[lead + rows]
                x = self.at_rest[lead:].astype(complex)
            else:
                states += mode_states(one, x, self.dt)[rows]
            drive = x[rows, None]
            for g, gc, gain in forces:
                states -= mode_states(one, gc, self.dt)[rows] * gain[None, r:r + 1]
                drive = drive - g[rows, None] * gain[None, r:r + 1]
            for o in self.orders:
                cols = _design(one, states, drive, self.t, o, self.starts if j == 0 else (), self.initial)
                pieces[o].append(cols if j == 0 else cols[:, :2])
        out = {o: np.hstack(p) for o, p in pieces.items()}
        if self.keep:
            self.kept[key] = out
            while len(self.kept) > self.keep:
                self.kept.popitem(last=False)
        return out

    def matrix(self, poles: np.ndarray, order: int) -> np.ndarray:
        """The design matrix (len(rows), blocks x m) of the responses of kinematic ``order``."""
        each = [self._mode(r, complex(lam))[order] for r, lam in enumerate(poles)]
        return np.stack(each, axis=2).reshape(self.rows.size, -1)


def _residue_drives(prep: Prepared, elements: tuple[Element, ...], forces) -> list:
    """``Columns``' drive of a modal model under the excitation and known element forces."""
    return [(prep.u, [(g, el.gain) for el, g in zip(elements, forces)])]


def fit_residues(poles: np.ndarray, prep: Prepared, rows: np.ndarray, elements: tuple[Element, ...] = (),
                 forces=(), at: np.ndarray | None = None, columns: Columns | None = None,
                 at_rest: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Residues C (k, m) for fixed poles by least squares on the measured responses over ``rows``, and the
    fitted outputs there (len(rows), k); with ``at``, the outputs at those rows instead, from the measured
    input alone (the forced response: the free response of the record's initial state fitted on ``rows``
    is left out, see ``fit_model``). ``forces``: element forces along the record (measured coordinates).
    ``columns``: the design's columns over ``rows`` under these elements and forces, kept between calls.

    ``at_rest``: a record that starts at rest has no initial state (``Columns``), so its hit fixes the
    input gains; every fit's last residues are solved so. The poles' refinements and the order's choice
    keep the initial state free: held to the hit, a hardening hammer decay, whose phase runs ahead of any linear
    model's, chose a stiffer linear part (independent seed 64, a clamped-clamped beam at 185.8 Hz and
    0.23 %: 190.8 Hz at 0.53 %, and its cubic was lost)."""
    m = poles.size
    drives = _residue_drives(prep, elements, forces)
    if columns is None:  # each mode built once for every kinematic order of this fit
        columns = Columns(prep, rows, drives, _starts(prep), keep=m, at_rest=at_rest)
    at_cols = None if at is None else Columns(prep, at, drives, keep=m, at_rest=at_rest)
    C = np.empty((len(prep.names), m), complex)
    fit = np.empty((rows.size if at is None else at.size, len(prep.names)))
    design: dict[int, tuple] = {}  # per kinematic order: the design matrix, its factorisation, the forced part at ``at``
    for i, kind in enumerate(prep.kinds):
        o = ORDER[kind]
        if o not in design:
            X = columns.matrix(poles, o)
            forced = None if at_cols is None else at_cols.matrix(poles, o)[:, :2 * m]
            design[o] = X, LeastSquares(X), forced
        X, ls, forced = design[o]
        y = prep.measured[rows, i] - (prep.base[rows, o] if prep.base_excited else 0.0)
        sol = ls.solve(y)
        C[i] = sol[:m] + 1j * sol[m:2 * m]
        if at is None:
            fit[:, i] = X @ sol + (prep.base[rows, o] if prep.base_excited else 0.0)
        else:
            fit[:, i] = forced @ sol[:2 * m] + (prep.base[at, o] if prep.base_excited else 0.0)
    return C, fit


def _per_response(fit: np.ndarray, meas: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean((fit - meas) ** 2, axis=0)) / np.maximum(meas.std(axis=0), 1e-300)


def check_errors(poles: np.ndarray, prep: Prepared, rows: np.ndarray, check: np.ndarray) -> np.ndarray:
    """Each response's NRMSE on the rows ``check`` of the model with these poles whose residues are fitted
    on ``rows``, from the measured input alone (see ``fit_residues``)."""
    _, fit = fit_residues(np.asarray(poles, complex), prep, rows, at=check)
    return _per_response(fit, prep.measured[check])


def _nrmse(fit: np.ndarray, meas: np.ndarray) -> float:
    return float(np.mean(_per_response(fit, meas)))


def admissible(poles: np.ndarray, prep: Prepared) -> bool:
    """Poles a refinement may return: stable, and every natural frequency below Nyquist (an unbounded
    search once sent a mode to 1e12 Hz with no damping, and every simulation of the baseline diverged)."""
    return bool(np.all(np.isfinite(poles)) and np.all(poles.real < 0) and np.all(poles.imag > 0)
                and np.all(np.abs(poles) < 2 * np.pi * 0.49 * prep.fs_hz))


def _zeta(poles: np.ndarray) -> np.ndarray:
    """Damping ratios of poles (safe at a pole at zero)."""
    return -poles.real / np.maximum(np.abs(poles), 1e-300)


def structural(poles: np.ndarray, prep: Prepared) -> np.ndarray:
    """Which poles are structural modes: lightly damped (zeta < 0.3), inside the band the data carry
    power in."""
    f = np.abs(poles) / (2 * np.pi)
    return (_zeta(poles) < 0.3) & (f >= prep.band[0]) & (f <= prep.band[1])


def drivable(poles: np.ndarray, prep: Prepared) -> np.ndarray:
    """Which modes a force at a location may drive: structural ones whose decay the record resolves
    (zeta_r |lambda_r| x its duration >= ``RESOLVED``).

    A fit keeps poles no structure has, because they cut its error: an undamped pole at a stepped sine's
    line (independent seed 0: 17.8 Hz at zeta 1e-229), one far below the band that fits the drift of
    integrated accelerations (seed 5: 0.015 Hz, a residue 1e5 times the modes'). Given a force's gain,
    the first rated the location's one mode (its resonance 1 / zeta is unbounded) and the second made
    every element's simulation leave its bound (35 of 38 candidates)."""
    return structural(poles, prep) & (_zeta(poles) * np.abs(poles) * prep.n / prep.fs_hz >= RESOLVED)


ZETA_MAX = 0.99  # the largest damping ratio a fitted baseline's pole keeps (``undegenerate``)


def bounded(poles: np.ndarray) -> np.ndarray:
    """The poles with damping ratios above ``ZETA_MAX`` brought down to it, the decay rate kept."""
    poles = np.asarray(poles, complex)
    return poles.real + 1j * np.maximum(poles.imag, np.sqrt(1.0 - ZETA_MAX ** 2) / ZETA_MAX * np.abs(poles.real))


def undegenerate(model: LinearModel, prep: Prepared, rows: np.ndarray) -> tuple[LinearModel, float] | None:
    """The fitted model with its poles above ``ZETA_MAX`` brought down to it and the residues fitted again
    on ``rows`` (with the fit's NRMSE there); None where every pole is below.

    A pole of the fit can end at zeta = 1 with an imaginary part near zero: the pair p, conj(p) is then one
    real pole twice, its two columns of the design nearly the same, and the residues that tell them apart
    huge (independent seed 28, a chain with nothing hidden: two such pairs at 30.1 and 26.6 Hz, residues
    4e10). Each block's state, read off the data through those columns, starts every free run off: the
    held-out blocks ran free at 0.34; with the pairs at zeta 0.99 and their residues fitted again, 0.12,
    and the baseline fitted in the band from there 0.032 (the instruments' noise floor 0.023). An
    overdamped pair at 0.99 follows a drift as well as a critically damped one.

    Only the fitted baseline is repaired, after its fit: capping the damping inside every pole search
    (the joint refits' too) moved eleven verdicts of the benchmark's hundred, five right ones lost and
    three gained (stop 65)."""
    p = np.asarray(model.poles, complex)
    if not np.any(_zeta(p) > ZETA_MAX):
        return None
    q = bounded(p)
    C, fit = fit_residues(q, prep, rows, at_rest=True)
    return LinearModel(q, np.ones((1, q.size), complex), C), _nrmse(fit, prep.measured[rows])


def refine_poles(poles: np.ndarray, prep: Prepared, rows: np.ndarray, elements=(), forces=(),
                 max_nfev: int = 20, stride: int = 2, free: np.ndarray | None = None) -> np.ndarray:
    """Poles by least squares on the fit error over ``rows`` (every ``stride``-th) with the residues solved
    inside; only the poles ``free`` marks move (all by default)."""
    sub = rows[::stride]
    scale = np.maximum(prep.measured[rows].std(axis=0), 1e-300)
    poles = np.asarray(poles, complex)
    free = np.ones(poles.size, bool) if free is None else np.asarray(free, bool)
    if not free.any():
        return poles
    full = np.concatenate([np.log(np.maximum(-poles.real, 1e-6)), np.log(poles.imag)])
    moves = np.concatenate([free, free])
    columns = Columns(prep, sub, _residue_drives(prep, elements, forces), _starts(prep), keep=2 * poles.size + 2)

    def unpack(x):
        y = full.copy()
        y[moves] = x
        m = y.size // 2
        out = poles.copy()
        with np.errstate(over="ignore", invalid="ignore"):  # a step the solver tries can overflow: not admissible
            out[free] = (-np.exp(y[:m]) + 1j * np.exp(y[m:]))[free]
        return out

    def resid(x):
        if not admissible(unpack(x), prep):
            return np.full(sub.size * scale.size, 1e3)
        _, fit = fit_residues(unpack(x), prep, sub, elements, forces, columns=columns)
        if not np.all(np.isfinite(fit)):
            return np.full(sub.size * scale.size, 1e3)
        return ((fit - prep.measured[sub]) / scale).ravel()

    try:
        x = least_squares(resid, full[moves], max_nfev=max_nfev, x_scale=0.01, diff_step=1e-5).x
    except NUMERIC_FAILURES:
        return poles
    return unpack(x) if admissible(unpack(x), prep) else poles


def fit_with_forces(poles0: np.ndarray, prep: Prepared, rows: np.ndarray, forces: list[np.ndarray],
                    max_nfev: int = 8) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], float]:
    """Poles, residues C (k, m) of the excitation and residues D_f (k, m) of each known force, fitted
    together (variable projection over the poles): nonlinear subspace identification's principle in the
    time domain, the nonlinear force as an extra input with residues of its own, so the linear part is
    not the equivalent linearisation of the nonlinear data (Noel & Kerschen, MSSP 2013). Returns the fit's
    NRMSE on ``rows`` too."""
    st = stride(prep, rows)
    hb = [convert(h, prep.fs_hz, prep.band, 0, 0) for h in forces]
    scale = np.maximum(prep.measured[rows].std(axis=0), 1e-300)

    def solve(poles, columns):
        m, sub = poles.size, columns.rows
        C = np.empty((len(prep.names), m), complex)
        D = [np.empty((len(prep.names), m), complex) for _ in hb]
        fit = np.empty((sub.size, len(prep.names)))
        # the forced and free responses' columns come first
        first = 2 * m * (1 + columns.initial + len(prep.blows))
        design: dict[int, tuple] = {}  # per kinematic order: the design matrix and its factorisation
        for i, kind in enumerate(prep.kinds):
            o = ORDER[kind]
            if o not in design:
                X = columns.matrix(poles, o)
                if not np.all(np.isfinite(X)):
                    raise ValueError("poles left the stable half-plane")
                design[o] = X, LeastSquares(X)
            X, ls = design[o]
            y = prep.measured[sub, i] - (prep.base[sub, o] if prep.base_excited else 0.0)
            sol = ls.solve(y)
            C[i] = sol[:m] + 1j * sol[m:2 * m]
            for j in range(len(hb)):
                q = sol[first + 2 * m * j:first + 2 * m * (j + 1)]
                D[j][i] = q[:m] + 1j * q[m:]
            fit[:, i] = X @ sol + (prep.base[sub, o] if prep.base_excited else 0.0)
        return C, D, fit

    def unpack(x):
        m = x.size // 2
        return -np.exp(x[:m]) + 1j * np.exp(x[m:])

    sub = rows[::st]
    drives = [(x, []) for x in [prep.u] + hb]
    columns = Columns(prep, sub, drives, _starts(prep), keep=2 * poles0.size + 2)

    def resid(x):
        if not admissible(unpack(x), prep):
            return np.full(sub.size * scale.size, 1e3)
        try:
            return ((solve(unpack(x), columns)[2] - prep.measured[sub]) / scale).ravel()
        except NUMERIC_FAILURES:
            return np.full(sub.size * scale.size, 1e3)

    x0 = np.concatenate([np.log(np.maximum(-poles0.real, 1e-6)), np.log(poles0.imag)])
    try:
        poles = unpack(least_squares(resid, x0, max_nfev=max_nfev, x_scale=0.01, diff_step=1e-5).x)
    except NUMERIC_FAILURES:
        poles = np.asarray(poles0, complex)
    if not admissible(poles, prep):
        poles = np.asarray(poles0, complex)
    C, D, fit = solve(poles, Columns(prep, rows, drives, _starts(prep), keep=poles.size, at_rest=True))
    return poles, C, D, _nrmse(fit, prep.measured[rows])


def underlying_frf(prep: Prepared, rows: np.ndarray,
                   forces: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray] | None:
    """The underlying linear structure's FRF (lines, (k, lines)), estimated with the nonlinear forces as
    extra inputs (``miso_frf``) over ``rows``, on the lines where the excitation carries power in the band;
    None for a transient excitation (a record of hammer hits: Welch's averages assume a stationary one; its
    training rows alone need not look impulsive)."""
    if prep.transient or not forces:
        return None
    u = prep.u[rows]
    hb = np.column_stack([convert(h, prep.fs_hz, prep.band, 0, 0)[rows] for h in forces])
    f, H, puu = miso_frf(np.column_stack([u, hb]), prep.zva[0][rows], prep.fs_hz)
    lo, hi = prep.band
    inside = (f >= lo) & (f <= hi)
    keep = inside & (puu > 1e-3 * puu[inside].max()) & np.all(np.isfinite(H), axis=0)
    return f[keep], H[:, keep]


def underlying_poles(prep: Prepared, rows: np.ndarray, forces: list[np.ndarray], n_modes: int,
                     lines: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray | None:
    """Poles of the underlying linear structure: vector fitting of its FRF (``underlying_frf``, or ``lines``
    if given: one estimate for several orders); None where there is no such FRF or too few lines."""
    lines = underlying_frf(prep, rows, forces) if lines is None else lines
    if lines is None or lines[0].size < 4 * n_modes:  # as few lines per mode as the first fit's order search allows
        return None
    try:
        poles = vector_fit_poles(lines[0], lines[1], n_modes)
    except NUMERIC_FAILURES:
        return None
    return poles if admissible(poles, prep) else None


def gains_from_residues(C: np.ndarray, D: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The modal gains g of a force whose responses have residues D (k, m), in a model with residues C:
    D_ir = -C_ir g_r, by least squares over the responses (each weighted by ``weights``)."""
    w = np.asarray(weights, float)[:, None] ** 2
    return -np.sum(w * np.conj(C) * D, axis=0) / np.maximum(np.sum(w * np.abs(C) ** 2, axis=0), 1e-300)


def _relocation_basis(s: np.ndarray, poles: np.ndarray) -> np.ndarray:
    a = poles[None, :]
    s = s[:, None]
    out = np.empty((s.shape[0], 2 * poles.size), complex)
    out[:, 0::2] = 1 / (s - a) + 1 / (s - a.conj())
    out[:, 1::2] = 1j / (s - a) - 1j / (s - a.conj())
    return out


def vector_fit_poles(f_hz: np.ndarray, H: np.ndarray, n_modes: int, iterations: int = 15) -> np.ndarray:
    """Common poles (Im > 0) of the frequency responses H (k, nf) by vector fitting."""
    s = 2j * np.pi * f_hz
    k, nf = H.shape
    w = 1.0 / np.sqrt(np.mean(np.abs(H) ** 2, axis=1, keepdims=True) + 1e-300)
    beta = 2 * np.pi * np.linspace(f_hz.min(), f_hz.max(), n_modes + 2)[1:-1]
    poles = -0.01 * beta + 1j * beta
    m2 = 2 * n_modes
    for _ in range(iterations):
        Phi = _relocation_basis(s, poles)
        A = np.zeros((k * nf, k * m2 + m2), complex)
        b = np.zeros(k * nf, complex)
        for i in range(k):
            A[i * nf:(i + 1) * nf, i * m2:(i + 1) * m2] = Phi * w[i]
            A[i * nf:(i + 1) * nf, k * m2:] = -(H[i] * w[i])[:, None] * Phi
            b[i * nf:(i + 1) * nf] = H[i] * w[i]
        x = np.linalg.lstsq(np.vstack([A.real, A.imag]), np.concatenate([b.real, b.imag]), rcond=None)[0]
        ct = x[k * m2:]
        Ar = np.zeros((m2, m2))
        br = np.zeros(m2)
        for r, a in enumerate(poles):
            Ar[2 * r:2 * r + 2, 2 * r:2 * r + 2] = [[a.real, a.imag], [-a.imag, a.real]]
            br[2 * r] = 2.0
        eig = np.linalg.eigvals(Ar - np.outer(br, ct))
        new = eig[eig.imag > 1e-9 * np.abs(eig).max()]
        new = -np.abs(new.real) + 1j * np.abs(new.imag)
        if new.size < n_modes:  # lost pairs: put them back spread over the band
            add = 2 * np.pi * np.linspace(f_hz.min(), f_hz.max(), n_modes - new.size + 2)[1:-1]
            new = np.concatenate([new, -0.01 * add + 1j * add])
        poles = np.sort_complex(new[:n_modes])
    return poles[np.argsort(poles.imag)]


def peak_poles(f_hz: np.ndarray, H: np.ndarray, n_modes: int, zeta: float = 0.02) -> np.ndarray | None:
    """Poles at the ``n_modes`` highest peaks of the responses' FRF magnitudes, each response scaled to
    its own largest (peak picking, so a mode that one sensor alone sees counts as much as one every sensor
    sees), at damping ratio ``zeta``; None if there are fewer peaks."""
    a = np.sum((np.abs(H) / (np.abs(H).max(axis=1, keepdims=True) + 1e-300)) ** 2, axis=0)
    inner = np.flatnonzero((a[1:-1] >= a[:-2]) & (a[1:-1] > a[2:])) + 1
    if inner.size < n_modes:
        return None
    top = np.sort(inner[np.argsort(a[inner])[::-1][:n_modes]])
    w = 2 * np.pi * f_hz[top]
    return -zeta * w + 1j * w


def gliding(poles: np.ndarray, prep: Prepared, span: int | None = None) -> bool:
    """Does a one-response fit hold two resonant modes that are an unresolved pair (``_unresolved_pairs``):
    one mode gliding with amplitude?"""
    return bool(np.any(_unresolved_pairs(poles, prep, span)))


def glide_partners(poles: np.ndarray, prep: Prepared) -> np.ndarray:
    """Of a one-response fit's resonant poles, those that make an unresolved pair with a more lightly damped
    one (``gliding``): the pair is one mode gliding with amplitude, and the lighter is the mode at small
    amplitude, the linear part (the other follows the loud start of the decay, which fades faster)."""
    pairs = _unresolved_pairs(poles, prep)
    z = _zeta(np.asarray(poles, complex))
    return np.any(pairs & (z[None, :] < z[:, None]), axis=1)


def _unresolved_pairs(poles: np.ndarray, prep: Prepared, span: int | None = None) -> np.ndarray:
    """(m, m): which two of a one-response fit's resonant modes (``structural``) are closer in frequency than
    their half-power bandwidths and the record's frequency resolution add up to (none with more responses;
    the resolution of ``span`` samples where the response lasts only so long, a hammer's decay). One response
    cannot tell such a pair from one mode whose frequency moves with amplitude (several sensors can: the
    pair's shapes differ, as a rig's two beams' do)."""
    poles = np.asarray(poles, complex)
    if len(prep.names) != 1:
        return np.zeros((poles.size, poles.size), bool)
    f, z = np.abs(poles) / (2 * np.pi), _zeta(poles)
    resonant = structural(poles, prep)
    close = np.abs(f[:, None] - f[None, :]) < (z * f)[:, None] + (z * f)[None, :] + prep.fs_hz / (span or prep.n)
    return close & resonant[:, None] & resonant[None, :] & ~np.eye(poles.size, dtype=bool)


def stride(prep: Prepared, rows: np.ndarray, cap: int = 20000) -> int:
    """Every how many samples the pole refinement looks: eight per period of the band's top, and at most
    ``cap`` samples (the residues are a linear fit, the poles need the shape of the response, not every
    sample of it)."""
    return max(1, int(prep.fs_hz / (8 * prep.band[1])), int(np.ceil(rows.size / cap)))


LOUD = 8.0  # a response stands out of its noise at this many times its median absolute value


def decay_rows(prep: Prepared, rows: np.ndarray) -> np.ndarray | None:
    """Of ``rows``, those up to the last where a response stands out of its noise (``LOUD`` times its median
    absolute value over the rows): a hammer record's decay; None where no response does."""
    y = np.abs(prep.measured[rows])
    loud = np.any(y > LOUD * np.median(y, axis=0), axis=1)
    if not loud.any() or rows[loud][-1] == rows[0]:
        return None
    return rows[rows <= rows[loud][-1]]


def band_lines(prep: Prepared, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The FRF (lines, (k, lines)) the starting poles are fitted to: over ``rows``, on the band's lines where
    the excitation carries at least 1e-3 of its largest power there (none where the band holds no line).

    A hammer record's input is its hit, and this FRF is taken over the whole record, which holds it: a record
    that starts at the hit has it inside the band-pass's edge, before the first row, and a force channel that
    reads zero after it left the rows no input at all (independent seeds 176 and 197, clamped-clamped beams
    hit 3 and 10 ms into 7.5 and 8.5 s records: "power on too few frequency lines", 3 of 474 and 1,842)."""
    src = np.arange(prep.n) if prep.transient else rows
    f, H, puu = frf(prep.u[src], prep.zva[0][src], prep.fs_hz)
    lo, hi = prep.band
    inside = (f >= lo) & (f <= hi)
    if not inside.any():
        return f[:0], H[:, :0]
    keep = inside & (puu > 1e-3 * puu[inside].max())
    return f[keep], H[:, keep]


def fit_model(prep: Prepared, rows: np.ndarray, max_modes: int = MAX_MODES,
              poles0: np.ndarray | None = None, check: np.ndarray | None = None,
              decay: np.ndarray | None = None) -> tuple[LinearModel, float]:
    """The modal model of the lowest order after which two more modes no longer cut the error of any
    response by 10 % (and 0.005); returns it with its fit error on ``rows`` (NRMSE, mean over responses).

    The error that chooses the order is, when ``check`` is given, the model's on those rows (which the
    fit did not see) from the measured input alone, else its fit error on ``rows``. On a nonlinear record
    every extra mode cuts the fit error: a pole with next to no damping lets its free response run through
    the whole record as one more sinusoid, which on a periodic or stepped excitation fits the steady
    response of a nonlinear structure at that line (independent Duffing seed 23: seven modes, four of
    them undamped, where the generator has one; held-out NRMSE 0.41 against a fit error of 0.03). What
    the input alone makes on rows the fit did not see is what such modes cannot fake. With ``poles0`` (a
    fit of the same data in another band) the order is taken from it and only refined.

    With ``decay`` (a hammer record's decay, ``decay_rows``) the order is chosen on those rows instead:
    each order's error there from the input alone, the record at rest before its hit where it is
    (``Prepared.rest_until``), and two modes closer than the decay can resolve are one gliding mode
    (``gliding`` over the decay's span: a hardening decay of 0.4 s is not two modes 3.8 Hz apart,
    independent seed 4)."""
    st = stride(prep, rows)
    at_rest, span = False, None
    if decay is not None:
        check, at_rest, span = decay, prep.rest_until is not None, int(decay[-1] - decay[0] + 1)
    if poles0 is not None:
        poles0 = np.asarray(poles0, complex)
        poles = refine_poles(poles0, prep, rows, max_nfev=30, stride=st)
        if np.sum(drivable(poles, prep)) < np.sum(drivable(poles0, prep)):
            # a refinement may not turn a mode whose decay the record resolves into a sinusoid it cannot
            # (independent seed 64, a clamped-clamped beam's hardening hammer decay: 185.96 Hz at zeta
            # 0.23 % from the first fit, the beam's 185.84 Hz at 0.23 %, went to 191.5 Hz at zeta 5e-27
            # on the training blocks' glide, and the baseline held out 11.5 times worse than zero)
            poles = poles0
        C, fit = fit_residues(poles, prep, rows, at_rest=True)
        m = poles.size
        return LinearModel(poles, np.ones((1, m), complex), C), _nrmse(fit, prep.measured[rows])
    # (the starting poles from ``band_lines``; refined and the order chosen on ``rows``)
    f, H = band_lines(prep, rows)
    if f.size < 8:
        raise ValueError(f"the excitation has power on {f.size} frequency line(s) in the band, too few to fit a "
                         "modal model (at least 8): a single sine does not show the structure's modes; give "
                         "--model RIG.yaml for a rig model as the baseline, or --fit-data with a broadband, swept or "
                         "stepped record of the same structure")
    scored = prep.measured[rows if check is None else check]
    kept, misses = None, 0
    for m in range(1, min(max_modes, f.size // 4) + 1):
        # two starts per order, the better refined one kept: vector fitting's poles, and poles at the
        # FRF's peaks. On few lines (a stepped sine) vector fitting can put two modes where one is and
        # miss a mode that one sensor alone sees (independent seed 61: 13.97 and 14.51 Hz where the
        # beams' modes are near 13.2 and 15.1; the second beam's held-out error went from 1.27 to 2.1)
        tried = []
        for start in (vector_fit_poles, peak_poles):
            try:
                poles = start(f, H, m)
                if poles is None:
                    continue
                poles = refine_poles(poles, prep, rows, max_nfev=12, stride=2 * st)
                C, fit = fit_residues(poles, prep, rows, at=check, at_rest=at_rest)
            except NUMERIC_FAILURES:
                continue
            tried.append((_per_response(fit, scored), poles, C))
        if not tried:
            break
        each, poles, C = min(tried, key=lambda t: float(np.sum(t[0])))
        resonant = structural(poles, prep)
        if not np.any(resonant):  # nothing resonates: no order to choose
            continue
        # with one response, two modes closer than their bandwidths are one mode gliding with amplitude
        # (independent seed 64, a clamped-clamped beam's hardening hammer decay: 192.6 and 195.1 Hz where
        # the beam has one mode at 185.8 Hz, and the cubic then lost to a quadratic stiffness)
        if gliding(poles, prep, span):
            misses += 1
            if misses == 2:
                break
            continue
        # more modes are kept when they predict any response better: a sensor on a beam whose mode the
        # others barely see must get its mode too
        if kept is None or np.any((each < 0.9 * kept[0]) & (kept[0] - each > 0.005)):
            kept, misses = (each, poles, C), 0
        else:
            misses += 1  # a mode can pair up with a neighbour first: look two orders further
            if misses == 2:
                break
    if kept is None:
        raise ValueError("no modal model could be fitted to the data")
    err, poles, C = kept
    refined = refine_poles(poles, prep, rows, max_nfev=30, stride=st)
    poles = refined if np.any(structural(refined, prep)) else poles
    C, fit = fit_residues(poles, prep, rows, at_rest=True)
    m = poles.size
    return LinearModel(poles, np.ones((1, m), complex), C), _nrmse(fit, prep.measured[rows])


class ModalBaseline(Baseline):
    """A modal model fitted to the data (see the module's docstring)."""

    label = "modal model fitted to the data"
    causes = ("contact", "cubic_stiffness", "quadratic_stiffness", "coulomb_friction", "quadratic_damping",
              "hysteretic_joint", "linear_mismatch", "clipping")

    def __init__(self, model: LinearModel, driving_point: int | None, fit_nrmse: float = np.nan,
                 drivable: np.ndarray | None = None, driving_sign: int = 1):
        self.model = model
        self.driving_point = driving_point
        self.driving_sign = driving_sign  # -1: the driving point's response reads against the force as prepared
        self.fit_nrmse = fit_nrmse
        # the modes a force may drive (``drivable``); all of them when none qualifies
        mask = np.ones(model.poles.size, bool) if drivable is None else np.asarray(drivable, bool)
        self.drivable = mask if mask.any() else np.ones(model.poles.size, bool)

    @classmethod
    def fit(cls, prep: Prepared, rows: np.ndarray, max_modes: int = MAX_MODES,
            poles0: np.ndarray | None = None, check: np.ndarray | None = None,
            decay: np.ndarray | None = None) -> "ModalBaseline":
        model, err = fit_model(prep, rows, max_modes, poles0, check, decay)
        repaired = undegenerate(model, prep, rows)
        if repaired is not None:
            model, err = repaired
        return cls(model, prep.driving_point if prep.excitation_kind == "force" else None, err,
                   drivable(model.poles, prep))

    def coordinate_modes(self, loc: Location) -> np.ndarray:
        """The location's modal coefficients in the modes a force may drive (``drivable``), zero in the
        others: a pole below the band that fits the drift of integrated accelerations (independent seed
        5: 0.015 Hz, residue 1e5 x the modes') moves no structure's coordinate, and read into it, made
        the coordinate's velocity follow the input 200-fold (2 Re(b . lz), zero for a structure) and
        every velocity law's simulation leave its bound."""
        return np.where(self.drivable, loc.lz(self.model), 0.0)

    def _omega2i(self) -> np.ndarray:
        return 2j * self.model.poles.imag

    def _modes(self, lz: np.ndarray) -> np.ndarray:
        """The location's modes for separate gains: the largest |lz_r| / (zeta_r |lambda_r|), at most
        ``BASIS_MODES``, each moving the coordinate at least 10 % as much as the first."""
        p = self.model.poles
        score = np.abs(lz) / (np.maximum(-p.real / np.abs(p), 1e-4) * np.abs(p))
        score = np.where(self.drivable, score, -1.0)
        order = np.argsort(score)[::-1][:int(self.drivable.sum())]
        return np.array([r for r in order[:BASIS_MODES] if score[r] >= 0.1 * score[order[0]]], int)

    def gain_basis(self, loc: Location) -> list[np.ndarray]:
        lz = self.coordinate_modes(loc)
        m = lz.size
        if self.driving_point is not None:
            # reciprocity holds per mode where the driving point moves in it: its residue at least 5 % of
            # the mode's largest (a threshold against all modes' largest let one wide pseudo-mode below
            # the band, with a large residue, switch every structural mode off)
            cd = self.driving_sign * self.model.C[self.driving_point]
            ok = (np.abs(cd) >= 0.05 * np.abs(self.model.C).max(axis=0)) & self.drivable
            return [without_feedthrough(lz, np.where(ok, lz / np.where(ok, cd, 1.0), 0.0))]
        # one real coefficient per mode: without its feedthrough a mode's gain is a real multiple of
        # i conj(lz_r), whatever the excitation's participation (a second, complex coefficient for a
        # voltage-driven shaker's complex participation would be the same direction again)
        out = []
        for r in self._modes(lz):  # the dominant mode's first: one_sign keeps it in every subset
            e = np.zeros(m, complex)
            e[r] = lz[r] * self._omega2i()[r]
            out.append(without_feedthrough(lz, e))
        return out

    def per_mass(self, loc: Location, gain: np.ndarray) -> float:
        lz = self.coordinate_modes(loc)
        r = dominant_mode(lz, self.model.poles)
        x = lz[r] * self._omega2i()[r]
        if abs(x) == 0:
            return float("nan")
        # gain_r = x kappa_r theta  ->  per mass = theta kappa_r x^2 = gain_r x
        return float(np.real(gain[r] * x))

    def per_mass_mode_hz(self, loc: Location) -> float | None:
        r = dominant_mode(self.coordinate_modes(loc), self.model.poles)
        return float(self.model.frequencies_hz[r])

    def basis_signs(self, loc: Location, gains: list[np.ndarray]) -> np.ndarray | None:
        """A force at one place enters every mode through that mode's mass, which is positive: per gain
        of the basis (each is one mode's) the sign of what ``per_mass`` reads for a unit coefficient,
        read in that gain's own mode rather than the location's dominant one."""
        if len(gains) < 2:
            return None
        x = self.coordinate_modes(loc) * self._omega2i()
        return np.array([np.sign(float(np.real(np.sum(g * x)))) for g in gains])

    def physical(self, loc: Location) -> float | None:
        if self.driving_point is None:
            return None
        lz = self.coordinate_modes(loc)
        r = dominant_mode(lz, self.model.poles)
        cd = self.driving_sign * self.model.C[self.driving_point, r]
        inv = float(np.real(lz[r] ** 2 * self._omega2i()[r] / cd)) if cd != 0 else 0.0
        return 1.0 / inv if inv > 0 else None

    def initial_state(self, prep: Prepared, model: LinearModel, start: int, stop: int) -> np.ndarray:
        return estimate_state(model, prep, start, stop)

    def fit_jointly(self, prep: Prepared, rows: np.ndarray, loc: Location, forces: list[np.ndarray]):
        """The linear part fitted again with the forces (unit-coefficient laws on the location's measured
        coordinate) as extra inputs: the new baseline, each force's modal gains, and the fit's NRMSE."""
        poles, C, D, err = fit_with_forces(self.model.poles, prep, rows, forces)
        # from the baseline's poles the fit can stop far from the linear part of strongly nonlinear data
        # (independent seed 47, a hardening Duffing oscillator at 26.2 Hz with 1 % damping: 24.6 Hz with
        # 10 %, fit error 0.28): it starts again from the modes of the underlying linear FRF, the forces
        # conditioned out (26.0 Hz, then 26.3 Hz with 1.07 %, fit error 0.02), and keeps the better fit
        lines = underlying_frf(prep, rows, forces)
        start = underlying_poles(prep, rows, forces, poles.size, lines)
        if start is not None:
            again = fit_with_forces(start, prep, rows, forces)
            if again[3] < err:
                poles, C, D, err = again
        # a mode more where the baseline has fewer structural modes than there are responses, when it cuts
        # the joint fit's error by the order search's 10 %: a stopper that one beam strikes through the
        # record leaves no linear resonance of that beam for the order search to see (the equivalent
        # linearisation smears it), while its underlying mode stands out once the stopper's force is an
        # input (independent seed 552: two beams, one fitted mode, the stopper found only with two).
        # Not beyond the responses' count: on one response the extra pole split the single resonance of a
        # Duffing oscillator in two (seed 23, its cubic then named a contact)
        if np.count_nonzero(self.drivable) < len(prep.names):
            start = underlying_poles(prep, rows, forces, poles.size + 1, lines)
            if start is not None:
                again = fit_with_forces(start, prep, rows, forces)
                if again[3] < 0.9 * err:
                    poles, C, D, err = again
        scale = 1.0 / np.maximum(prep.measured[rows].std(axis=0), 1e-300)
        m = poles.size
        new = ModalBaseline(LinearModel(poles, np.ones((1, m), complex), C), self.driving_point, err,
                            drivable(poles, prep), self.driving_sign)
        lz = new.coordinate_modes(loc)
        with np.errstate(over="ignore", invalid="ignore"):  # a pseudo-mode's residue can be 1e160
            gains = [np.where(new.drivable, gains_from_residues(C, d, scale), 0.0) for d in D]
        return new, [without_feedthrough(lz, g) for g in gains], err

    def refit(self, prep: Prepared, segments, elements: tuple[Element, ...]) -> "ModalBaseline":
        rows = rows_of(segments)
        forces = [element_force(el, prep) for el in elements]
        try:
            # only the modes an element can drive move: the others (an undamped line of a stepped sine, a
            # drift) are the fit's devices, which the elements do not touch, and set free the search once
            # sent one to 401 Hz at zeta 1, where it held out three times worse (independent seed 45)
            poles = refine_poles(self.model.poles, prep, rows, elements, forces, max_nfev=10,
                                 stride=2 * stride(prep, rows), free=self.drivable)
            C, fit = fit_residues(poles, prep, rows, elements, forces, at_rest=True)
        except NUMERIC_FAILURES:
            return self
        m = poles.size
        return ModalBaseline(LinearModel(poles, np.ones((1, m), complex), C), self.driving_point,
                             _nrmse(fit, prep.measured[rows]), drivable(poles, prep), self.driving_sign)

    def through(self, driving_point: int, sign: int) -> "ModalBaseline":
        """The same model with its reciprocity taken through another response (``sign`` -1 where that
        response reads as a driving point read against the force as prepared)."""
        return ModalBaseline(self.model, driving_point, self.fit_nrmse, self.drivable, sign)


def estimate_state(model: LinearModel, prep: Prepared, start: int, stop: int) -> np.ndarray:
    """Modal state at ``start`` by least squares on the measured responses over [start, stop): the
    free response that, added to the forced one from rest, fits them best (linear part only)."""
    seg = slice(start, stop)
    poles = model.poles
    dt = 1.0 / prep.fs_hz
    u = prep.u[seg]
    states = mode_states(poles, u.astype(complex), dt)
    t = np.arange(stop - start) * dt
    rows, rhs = [], []
    for i, kind in enumerate(prep.kinds):
        o = ORDER[kind]
        lam = poles[None, :]
        forced = 2 * np.real((model.C[i] * lam**o * states).sum(axis=1))
        if o >= 1:
            forced += 2 * np.real((model.C[i] * poles ** (o - 1)).sum()) * u
        y = prep.measured[seg, i] - forced - (prep.base[seg, o] if prep.base_excited else 0.0)
        free = model.C[i] * lam**o * np.exp(lam * t[:, None])
        s = max(float(np.std(prep.measured[:, i])), 1e-300)
        rows.append(np.hstack([2 * free.real, -2 * free.imag]) / s)
        rhs.append(y / s)
    sol = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]
    m = poles.size
    return sol[:m] + 1j * sol[m:]
