"""The search: fit every cause at every location, refine the leaders by simulation, score on held-out
blocks, and select honestly.

1. Predictions. Every held-out block is simulated from the state the baseline reads off the data just
   before it (``predict``), band-passed like the measurement; its NRMSE is one sample of the paired test.
2. Regression. The residual (measured minus the baseline simulated over the whole record) is regressed
   on the linear responses to each cause's force shape evaluated on the measured coordinate of each
   location (Kaheman et al. 2019 learn such discrepancies in physical coordinates; Noel & Kerschen's
   nonlinear subspace method treats the nonlinear force as an extra input the same way). A shape with
   nonlinear parameters (a gap, a side, a slip displacement) is searched on a grid. Against a baseline
   fitted to the record each cause is also regressed with a spring and a damper at its coordinate
   (``regressions`` given ``spring_damper_responses``): the baseline holds the cause's equivalent stiffness
   and damping, the plain regression sees only what departs from them (a drag comes out a fiftieth of its
   size), and the spring and damper take that part out again. Those candidates are scored only where the
   rest found nothing (``discover``).
3. Refinement. The regression is biased (displacement integrated from noisy accelerations, a linear part
   that absorbed some of the effect), so each cause's best location is refined by simulation error on
   training blocks (``refine``): coefficients scaled, a gap scanned and polished, and a fitted baseline
   refitted jointly with the cause in place.
4. Selection (``select``). A cause is a finding only if a one-sided paired test over pieces of the
   held-out blocks says it beats the baseline (Wilcoxon's signed rank, p < ``alpha``), its gain exceeds
   ``gain_floor``, it predicts better than zero, and it beats every simpler significant cause (a paired
   t-test: between two causes the size of the difference counts, not only its sign); a cause the data
   cannot tell from another (no significant difference either way) is reported as ambiguous, with the
   test that would separate them. A second finding must add a significant gain on top of the first, in
   a test over whole blocks (``clustered_p``: the pieces of a block are not independent).
Numerical failures (an optimiser or linear algebra that does not converge) make a failed candidate
with its reason, never a crash.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import minimize
from scipy.stats import t as student_t, wilcoxon

from .baselines import Baseline, Location, dominant_mode
from .catalogue import (CAUSES, CONTACT, JOINT, ONSETS, SIDES, equivalent_coefficient, law_parameters,
                        shapes)
from .model import NUMERIC_FAILURES, Element, LinearModel, force_response, lstsq, nudging_gain, simulate, substeps_for
from .signals import MAX_SAMPLES, ORDER, Prepared, convert
from .split import Split, rows_of


ROUND_OFF = 1e-9  # pieces whose errors differ by at most this share of the larger are a tie (``signed_rank_p``)
NOISE_MARGIN = 2.0  # on a hammer record, a piece tests a model only where its motion is this many times the quietest's
MIN_RANK_PIECES = 5  # fewer pieces than this: the signed-rank test's p hangs on the count alone, the t-test decides
PENALTY = 1e9  # the refinement's objective where a simulation diverges or a parameter leaves its range
# a candidate that gains nothing over its own linear part on held-out blocks still may be a finding if over the
# training blocks it cuts that linear part's error by this share (``_own_gain_trained``): the cause acts there
ACTS_IN_TRAINING = 0.5
NUDGE_RATE = 0.3  # relaxation rate of the warm-up towards measured velocities, per rad/s of the slowest mode


@dataclass(frozen=True)
class Settings:
    # significance of the paired tests. 0.1, not 0.05: on the independent generator's 100 cases and their
    # 100 twins (the selection replayed exactly, stop 35) it names 66 right against 63 and the rig
    # generator's 40 cases 36 against 35; no effect-free record (18 "none" cases, 100 twins, the rig's 4)
    # gets a finding more. The gain floor and the tests between causes keep the twins clean, not alpha.
    alpha: float = 0.1
    gain_floor: float = 0.03  # a finding must cut the held-out error by at least this share (>= 0: ``score``)
    refine_evals: int = 60  # simulations per refinement
    refine_blocks: int = 6  # training blocks a refinement simulates (the busiest at the location)
    max_locations: int = 6  # locations searched in full (ranked by how much of the residual they explain)
    max_refined: int = 4  # causes refined by simulation (each at its best location, best regressions first)
    max_joint: int = 6  # with a fitted baseline: the best regressions fitted again jointly with the linear part
    max_samples: int = MAX_SAMPLES  # samples x responses analysed at most (``signals.within_budget``)


@dataclass(frozen=True)
class Candidate:
    cause: str
    location: str
    parameters: dict  # the catalogue's, per unit modal mass at the location
    elements: tuple[Element, ...] = ()
    output: tuple = ()  # sensor causes: ((response index, "gain" | "clip", value),)
    physical: dict = field(default_factory=dict)  # in newtons when the baseline knows the mass
    fit_r2: float = float("nan")  # share of the training residual the regression explains
    train_nrmse: float = float("nan")
    block_errors: np.ndarray | None = None
    test_nrmse: float = float("nan")
    gain: float = float("nan")  # 1 - test NRMSE / baseline test NRMSE
    p_value: float = float("nan")  # paired test against the baseline
    own_gain: float = float("nan")  # 1 - test NRMSE / that of its own linear part alone (refitted with it)
    own_gain_trained: float = float("nan")  # the same over the training blocks (``score``: where it is asked)
    own_p: float = float("nan")  # the signed-rank test against that linear part alone (``over_own_part``)
    refined: bool = False
    baseline: Baseline | None = None  # its own linear part when refitted jointly
    note: str = ""

    @property
    def order(self) -> int:
        """Fitted numbers, for the parsimony rule: the cause's, and a compensation's spring and damper."""
        return CAUSES[self.cause].order + len(compensation(self))

    @property
    def label(self) -> str:
        return f"{self.cause} at {self.location}"


def outputs_of(prep: Prepared) -> list[tuple[int, int]]:
    return [(i, ORDER[k]) for i, k in enumerate(prep.kinds)]


def bandpass(prep: Prepared, y: np.ndarray) -> np.ndarray:
    """Predictions band-passed like the measured responses (each in its own kind)."""
    return convert(y, prep.fs_hz, prep.band, 0, 0)


def predict(baseline: Baseline, model: LinearModel, prep: Prepared, seg: slice, warm: int,
            output: tuple = (), bound: float = np.inf, past: int = 0) -> np.ndarray:
    """The responses over ``seg`` (each in its measured kind, absolute, band-passed) of ``model`` started
    ``warm`` samples earlier from the state ``baseline`` reads off the data there, and nudged towards the
    measured velocities until the segment starts (``model.simulate``); the segment itself is free-run.

    With ``past`` > 0 the simulation runs on that many samples past the segment (as far as the record
    goes) before it is band-passed, so the band-pass's edge effect falls outside the segment. Scoring
    cuts at the segment's end (``past`` = 0): there the last tenth of a second of a block can err up to
    80 times its median error (independent seed 59), noise that the selection's thresholds were set
    with; run on, tiny real mismatches became findings (a 0.4 % sensor gain on the project's own
    recording), so the fix for scoring waits for thresholds that know the noise floor."""
    s = max(0, seg.start - warm)
    stop = min(prep.n, seg.stop + past)
    w0, nudge = None, None  # at rest where the record starts
    if seg.start > s:
        w0 = baseline.initial_state(prep, model, s, seg.start)
        rate = float(np.min(np.abs(model.poles))) * NUDGE_RATE
        Co, K = nudging_gain(model, rate)
        observed = prep.zva[1][s:seg.start + 1].copy()
        for i, kind, value in output:  # a sensor reading high: the structure moved less than it says
            if kind == "gain":
                observed[:, i] /= 1.0 + value
        nudge = (observed, Co, K)
    zmax = float(np.max(np.abs(prep.zva[0][s:stop]))) if prep.n else 0.0
    vmax = float(np.max(np.abs(prep.zva[1][s:stop]))) if prep.n else 0.0
    sub = substeps_for(model, prep.fs_hz, 2 * zmax, 2 * vmax)
    y = simulate(model, prep.drive[s:stop], prep.fs_hz, outputs_of(prep), w0, sub, bound, nudge)
    if not np.all(np.isfinite(y)):
        return np.full((seg.stop - seg.start, y.shape[1]), np.nan)
    y = bandpass(prep, y)[:seg.stop - s]
    if prep.base_excited:  # the frame's own motion in each response's kind (already band-passed)
        y = y + prep.base[s:seg.stop][:, [ORDER[k] for k in prep.kinds]]
    for i, kind, value in output:
        if kind == "gain":
            y[:, i] *= 1.0 + value
        elif kind == "clip":
            y[:, i] = np.clip(y[:, i], -value, value)
    return y[seg.start - s:]


@dataclass(frozen=True)
class Scoring:
    """What every candidate is scored against: the baseline's errors per held-out block."""

    scale: np.ndarray  # (k,) std of each measured response over the held-out blocks
    block_errors: np.ndarray  # (pieces,)
    test_nrmse: float
    warm: int
    bound: float
    piece: int  # samples per piece of the paired test
    floor: float = 0.03  # the gain floor (``Settings.gain_floor``): below it the training blocks are asked too
    alpha: float = 0.1  # the tests' level (``Settings.alpha``)
    # the pieces the signed-rank tests count (``moving_pieces``); None: all
    tested: np.ndarray | None = None

    def rank_p(self, a: np.ndarray, b: np.ndarray) -> float:
        """``signed_rank_p`` over the pieces that test a model (``tested``)."""
        if self.tested is None:
            return signed_rank_p(a, b)
        return signed_rank_p(np.asarray(a)[self.tested], np.asarray(b)[self.tested])


def moving_pieces(prep: Prepared, segs, scale: np.ndarray, piece: int) -> np.ndarray | None:
    """On a hammer record (``Prepared.transient``), the held-out pieces whose measured motion (RMS over the
    piece, per response over ``scale``, mean over responses: ``block_errors``' measure) is at least
    ``NOISE_MARGIN`` times the quietest piece's; None on any other record, or where fewer than
    ``MIN_RANK_PIECES`` pieces are left.

    Once a decay has sunk into the sensor's noise, a piece holds noise alone, and every model predicts it
    equally well: the sign of a difference there is the noise's, and a rank test that counts those pieces
    asks whether the typical piece of noise improves. On independent seed 925 (a clamped-clamped beam hit
    by a hammer, a membrane cubic) 196 of the 235 held-out pieces move less than twice the quietest one
    (the median piece 1.5 times it): over all pieces the cubic's p against the baseline is 0.14, where the
    t-test gives 2e-4; over the 39 that move, 3e-5. A record that ends before its decay does loses its
    last, quietest pieces of motion from the test: power, not a bias."""
    if not prep.transient:
        return None
    rms = np.array([r for seg, k in zip(segs, pieces_per_block(segs, piece))
                    for r in piece_rms(prep.measured[seg], k, scale)])
    keep = rms >= NOISE_MARGIN * rms.min()
    return keep if np.count_nonzero(keep) >= MIN_RANK_PIECES else None


def simulation_bound(prep: Prepared) -> float:
    """The displacement beyond which a simulation counts as diverged: 50 times the record's largest."""
    return 50.0 * float(np.max(np.abs(prep.zva[0]))) + 1e-300


def block_errors(baseline: Baseline, model: LinearModel, prep: Prepared, segs, warm: int, scale: np.ndarray,
                 output: tuple = (), bound: float = np.inf, piece: int = 0) -> tuple[np.ndarray, float]:
    """NRMSE per piece (mean over responses of RMS error / the response's held-out std) and over all
    blocks together; inf where a simulation diverged. Each block is simulated once; with ``piece`` > 0
    its error is counted in pieces of that many samples (an effect that acts in a few blocks, a contact
    met only near a sweep's resonance, then shows in many samples of the paired test)."""
    errs, sq, count = [], np.zeros(scale.size), 0
    counts = pieces_per_block(segs, piece)
    for seg, k in zip(segs, counts):
        y = predict(baseline, model, prep, seg, warm, output, bound)
        if not np.all(np.isfinite(y)):
            return np.full(int(counts.sum()), np.inf), np.inf
        d = y - prep.measured[seg]
        errs += piece_rms(d, k, scale)
        sq += np.sum(d**2, axis=0)
        count += d.shape[0]
    return np.array(errs), float(np.mean(np.sqrt(sq / max(count, 1)) / scale))


def piece_rms(x: np.ndarray, k: int, scale: np.ndarray) -> list[float]:
    """The RMS of each of ``k`` pieces of ``x`` (samples, responses; split as ``np.array_split`` does), per
    response over ``scale``, mean over responses: ``block_errors``' NRMSE of an error, ``moving_pieces``'
    motion of a measured block."""
    return [float(np.mean(np.sqrt(np.mean(part**2, axis=0)) / scale)) for part in np.array_split(x, k)]


def pieces_per_block(segs, piece: int) -> np.ndarray:
    """How many pieces of ``piece`` samples ``block_errors`` counts in each block (one without pieces)."""
    return np.array([max(1, (s.stop - s.start) // piece) if piece else 1 for s in segs], int)


def paired_p(a: np.ndarray, b: np.ndarray) -> float:
    """One-sided p-value that errors ``b`` are smaller than ``a`` (paired t-test over their pairs): is the
    mean error smaller? What two candidates are compared by, where the size of a difference counts."""
    d = np.asarray(a, float) - np.asarray(b, float)
    if not np.all(np.isfinite(d)):
        return 1.0 if not np.all(np.isfinite(b)) else 0.0
    n = d.size
    sd = float(np.std(d, ddof=1)) if n > 1 else 0.0
    if sd == 0:
        return 0.0 if d.mean() > 0 else 1.0
    return float(student_t.sf(d.mean() / (sd / np.sqrt(n)), n - 1))


def clustered_p(a: np.ndarray, b: np.ndarray, counts: np.ndarray) -> float:
    """``paired_p`` with the pieces of each block taken together: the one-sided paired t-test over the
    blocks' mean differences. The pieces of a block are not independent samples (one initial state read
    off the data, one stretch of the excitation, a simulation error that carries from piece to piece),
    so a test over pieces overstates the evidence. Independent seed 2, a contact found at tip 1: a
    quadratic stiffness between the tips on top of it gained 0.03 at p = 0.020 over its 40 pieces, a
    false second finding; over its 8 blocks p = 0.18. ``counts``: pieces per block
    (``pieces_per_block``)."""
    d = np.asarray(a, float) - np.asarray(b, float)
    if not np.all(np.isfinite(d)) or d.size != int(np.sum(counts)):
        return paired_p(a, b)
    means = np.add.reduceat(d, np.concatenate([[0], np.cumsum(counts)[:-1]])) / counts
    return paired_p(means, np.zeros_like(means))


def signed_rank_p(a: np.ndarray, b: np.ndarray) -> float:
    """One-sided p-value that errors ``b`` are smaller than ``a`` in the typical piece (Wilcoxon's
    signed-rank test over the pieces): what a cause is tested against the baseline by.

    Against a baseline without the effect, the differences are heavy-tailed: large where the effect
    acts, and one piece the extended model predicts much worse (a contact's timing a little off) carries
    the t-test's variance. Independent seed 73, a cubic: better in 22 of 24 pieces, held-out gain 0.69,
    t-test p = 0.055; seed 90, a Coulomb friction: 15 of 16 pieces, gain 0.76, p = 0.059. The rank test
    asks whether most pieces improve, which such outliers do not undo (Demsar 2006 recommends it over
    the paired t-test for comparing predictors across data sets for the same reason). With fewer than
    ``MIN_RANK_PIECES`` pieces the t-test decides: the rank test's smallest p there, 2^-n, is at least
    1/16 and says only how many pieces improved (a 3 s rig record, 4 pieces all better by a sensor gain:
    p = 0.0625 whatever the gain, the t-test 0.026)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = a - b
    if not np.all(np.isfinite(d)):
        return paired_p(a, b)  # a diverged side
    # a piece both predict alike, exactly or to round-off, says nothing either way: dropped (Wilcoxon's own
    # rule for zero differences), and the test runs on the pieces that differ
    d = d[np.abs(d) > ROUND_OFF * np.maximum(np.abs(a), np.abs(b))]
    if d.size < MIN_RANK_PIECES:
        return paired_p(a, b)  # also no difference at all (p = 1)
    return float(wilcoxon(d, alternative="greater").pvalue)


def score(c: Candidate, baseline: Baseline, prep: Prepared, split: Split, sc: Scoring) -> Candidate:
    """Held-out errors of a candidate, its gain and its paired test against the baseline.

    A candidate that carries its own linear part (refitted with its force in place) is also scored
    against that linear part alone (``own_gain``; ``significant`` asks it to exceed the gain floor too):
    a refit with a force on the measured motion as an extra input can give the linear part a better fit
    for reasons of its own (the force takes up what the input cannot make: an unmodelled mode, a blow's
    ringing), and that gain is not the cause's (independent seed 3: a Coulomb friction whose linear part
    alone predicted 0.57 against the baseline's 1.50, and with the friction 0.56). The paired test stays
    against the baseline: against a linear part without its stopper the differences are heavy-tailed
    (large in the few pieces where the stopper acts) and a t-test misses what a contact adds (seed 2:
    own gain 0.55 at p = 0.07)."""
    own = c.baseline or baseline
    model = own.model.with_elements(c.elements)
    try:
        errs, nrmse = block_errors(own, model, prep, split.test, sc.warm, sc.scale, c.output, sc.bound, sc.piece)
    except NUMERIC_FAILURES as exc:
        return replace(c, block_errors=np.full(sc.block_errors.size, np.inf), test_nrmse=np.inf, gain=-np.inf,
                       p_value=1.0, note=f"failed: {exc}")
    gain = 1.0 - nrmse / sc.test_nrmse if np.isfinite(nrmse) and sc.test_nrmse > 0 else -np.inf
    # computed only for a candidate that gains at all: one that does not beat the baseline is no finding
    # whatever its own gain (``significant``: gain above a floor >= 0), and the check costs a second
    # simulation of every held-out block
    own_gain = own_trained = own_p = float("nan")
    comp = compensation(c)
    if (c.baseline is not None or comp) and c.elements and gain > 0:
        try:
            alone_errs, alone = block_errors(own, own.model.with_elements(comp), prep, split.test, sc.warm, sc.scale,
                                             (), sc.bound, sc.piece)
        except NUMERIC_FAILURES:
            alone_errs, alone = None, np.inf
        own_gain = 1.0 - nrmse / alone if np.isfinite(alone) and alone > 0 else 1.0
        own_p = sc.rank_p(alone_errs, errs) if alone_errs is not None else 0.0
        if not over_own_part(replace(c, own_gain=own_gain, own_p=own_p), sc.floor, sc.alpha):
            own_trained = _own_gain_trained(c, own, comp, prep, split, sc)
    p_value = sc.rank_p(sc.block_errors, errs)
    if CAUSES[c.cause].read_off_record and np.isfinite(nrmse):
        # a cause whose parameters are read off the record (a clipping's range: its extreme) is fitted on
        # no block, so every block tests it, the training blocks too: held out alone, a sweep's few clipped
        # pieces could not make a clipping significant (the rig generator's seed 20: 515 of its 668 clipped samples in
        # training blocks; gain 0.05 on the held-out ones, p = 0.16). Its gain and the comparisons with
        # other causes stay on the held-out pieces.
        try:
            base_all, _ = block_errors(baseline, baseline.model, prep, split.blocks, sc.warm, sc.scale, (), sc.bound,
                                       sc.piece)
            mine_all, _ = block_errors(own, model, prep, split.blocks, sc.warm, sc.scale, c.output, sc.bound, sc.piece)
            p_value = signed_rank_p(base_all, mine_all)
        except NUMERIC_FAILURES:
            pass
    return replace(c, block_errors=errs, test_nrmse=nrmse, gain=gain, p_value=p_value, own_gain=own_gain,
                   own_gain_trained=own_trained, own_p=own_p)


def _own_gain_trained(c: Candidate, own: Baseline, comp: tuple, prep: Prepared, split: Split, sc: Scoring) -> float:
    """1 - the candidate's simulation error over the training blocks / its own linear part's alone there.

    Asked where the held-out blocks show no gain over that linear part (``own_gain`` below the floor): a
    cause that acts in a few blocks, all of them training blocks, leaves the held-out ones to its linear
    part alone, which it made right. Independent seed 140, a hardening Duffing oscillator under a
    stepped sine that jumps in training blocks 5 and 6 (0 to 19): the modal baseline fitted through the
    jump (36.4 Hz, 3.3 % damping) holds out 0.78; refitted with the cubic, 33.40 Hz and 1.9 % (the
    generator's 33.39 Hz and 1.8 %), k3 within 4 %, held-out gain 0.82 over the baseline and none over
    that linear part alone; over the training blocks the linear part alone has 4.5 times the cubic's
    error (10.5 against 0.4 in the jump's blocks). It is in-sample: the linear part was fitted with the
    force in place, so without it does worse there by construction, and ``ACTS_IN_TRAINING`` asks much
    more than the floor (every other candidate asked on seeds 0-35 had at most 1.37 times, a share of 0.27;
    on seeds 0-99 no verdict moved)."""
    try:
        _, with_it = block_errors(own, own.model.with_elements(c.elements), prep, split.train, sc.warm, sc.scale,
                                  c.output, sc.bound)
        _, alone = block_errors(own, own.model.with_elements(comp), prep, split.train, sc.warm, sc.scale, (),
                                sc.bound)
    except NUMERIC_FAILURES:
        return float("nan")
    if not (np.isfinite(with_it) and np.isfinite(alone) and alone > 0):
        return float("nan")
    return 1.0 - with_it / alone


# --- regression ---------------------------------------------------------------------------------------


def force_responses(model: LinearModel, prep: Prepared, h: np.ndarray, gains: list[np.ndarray]) -> np.ndarray:
    """Band-passed responses (n, k, len(gains)) of the linear part to the force series h entering with
    each gain vector (the force band-passed first: for a linear model that is the same)."""
    hb = bandpass(prep, h[:, None])[:, 0]
    return force_response(model, hb, gains, outputs_of(prep), prep.fs_hz)


def baseline_residual(baseline: Baseline, prep: Prepared, split: Split, warm: int) -> np.ndarray:
    """Measured minus the baseline over the record (band-passed): simulated once from the state at the
    first training block when the baseline is linear, block by block when it has elements of its own or
    unmeasured blows struck (each block from the state read off the data before it)."""
    res = np.full((prep.n, len(prep.names)), np.nan)
    model = baseline.model
    if model.elements or prep.blows:
        for seg in split.train:
            res[seg] = prep.measured[seg] - predict(baseline, model, prep, seg, warm)
        return res
    start = min(s.start for s in split.blocks)
    seg = slice(start, prep.n)
    y = predict(baseline, model, prep, seg, warm)
    res[seg] = prep.measured[seg] - y
    return res


def regress(baseline: Baseline, prep: Prepared, rows: np.ndarray, residual: np.ndarray, loc: Location,
            cause_name: str, scale: np.ndarray, joint_shapes: int = 0) -> Candidate | None:
    """The cause at the location by least squares on the residual, the best shape on its grid. A
    baseline fitted to the data (``fit_jointly``) is then fitted again together with the force of each
    of the ``joint_shapes`` best shapes (its linear part had absorbed part of the effect), and the shape
    whose joint fit is best wins; the candidate carries that linear part as its own baseline."""
    return regressions(baseline, prep, rows, residual, loc, cause_name, scale, joint_shapes)[0]


def spring_damper_responses(baseline: Baseline, prep: Prepared, rows: np.ndarray, loc: Location,
                            scale: np.ndarray) -> np.ndarray | None:
    """The regression's columns (len(rows) k, 2 gains) of a unit spring and a unit damper at the location's
    coordinate: the same for every cause there, so made once per location (``regressions``' ``compensate``)."""
    gains = baseline.gain_basis(loc)
    if not gains:
        return None
    z, v = loc.coordinate(prep)
    return np.concatenate([force_responses(baseline.model, prep, col, gains)[rows] / scale[None, :, None]
                           for col in (z, v)], axis=2).reshape(rows.size * scale.size, -1)


def regressions(baseline: Baseline, prep: Prepared, rows: np.ndarray, residual: np.ndarray, loc: Location,
                cause_name: str, scale: np.ndarray, joint_shapes: int = 0,
                compensate: np.ndarray | None = None) -> tuple[Candidate | None, Candidate | None]:
    """``regress``'s candidate and, given ``compensate`` (``spring_damper_responses`` at the same location,
    rows and scale), the cause regressed together with a spring and a damper at its coordinate
    (``compensated``), from the same force responses (their simulation is the regression's cost)."""
    cause = CAUSES[cause_name]
    model = baseline.model
    z, v = loc.coordinate(prep)
    gains = baseline.gain_basis(loc)
    if not gains:
        return None, None
    target = (residual[rows] / scale).ravel()
    tt = float(target @ target)
    if tt <= 0:
        return None, None
    lz = baseline.coordinate_modes(loc)
    signs = baseline.basis_signs(loc, gains)
    found, with_lin = [], []
    for shp, cols in shapes(cause, z, v):
        X = np.concatenate([force_responses(model, prep, cols[:, c], gains)[rows] / scale[None, :, None]
                            for c in range(cols.shape[1])], axis=2).reshape(rows.size * scale.size, -1)
        if compensate is not None:
            got = _compensated_fit(baseline, loc, cause, shp, cols.shape[1], np.hstack([X, compensate]), target, tt,
                                   gains, lz)
            if got is not None:
                with_lin.append(got)
        try:
            theta = lstsq(X, target)
            if signs is not None and cols.shape[1] == 1:
                theta = one_sign(X, target, theta, signs, cause.positive)
        except np.linalg.LinAlgError:
            continue
        if not np.any(theta):
            continue
        r2 = 1.0 - float(np.sum((target - X @ theta) ** 2)) / tt
        elements = [Element(cause.code, law_parameters(cause, shp, c), lz, gain, loc.weights)
                    for c, gain in enumerate(column_gains(theta, gains, cols.shape[1]))]
        per_mass = [baseline.per_mass(loc, el.gain) for el in elements]
        if cause.positive and not all(pm > 0 for pm in per_mass):
            continue
        found.append((r2, shp, cols, tuple(elements), per_mass))
    comp = None
    if with_lin:
        r2, shp, elements, per_mass = max(with_lin, key=lambda f: f[0])
        n = len(cause.coefficients)
        params = _parameters(cause_name, shp, per_mass[:n]) | dict(zip(COMPENSATION, per_mass[n:]))
        comp = Candidate(cause_name, loc.name, params, elements,
                         physical=_physical(baseline, loc, cause_name, shp, elements[:n]), fit_r2=r2)
    if not found:
        return None, comp
    found.sort(key=lambda f: -f[0])
    r2, shp, cols, elements, per_mass = found[0]
    best = Candidate(cause_name, loc.name, _parameters(cause_name, shp, per_mass), elements,
                     physical=_physical(baseline, loc, cause_name, shp, elements), fit_r2=r2)
    if not joint_shapes or not hasattr(baseline, "fit_jointly"):
        return best, comp
    best_err = None
    for r2, shp, cols, _, _ in found[:joint_shapes]:
        try:
            own, jg, err = baseline.fit_jointly(prep, rows, loc, [cols[:, c] for c in range(cols.shape[1])])
        except NUMERIC_FAILURES:
            continue
        lz2 = own.coordinate_modes(loc)
        els = tuple(Element(cause.code, law_parameters(cause, shp, c), lz2, g, loc.weights)
                    for c, g in enumerate(jg))
        pm = [own.per_mass(loc, el.gain) for el in els]
        if cause.positive and not all(x > 0 for x in pm):
            continue
        if best_err is None or err < best_err:
            best_err = err
            best = Candidate(cause_name, loc.name, _parameters(cause_name, shp, pm), els,
                             physical=_physical(own, loc, cause_name, shp, els), fit_r2=r2, baseline=own)
    return best, comp


def column_gains(theta: np.ndarray, gains: list[np.ndarray], n_cols: int) -> list[np.ndarray]:
    """Each regressed column's modal gain vector: its coefficients (one per basis vector in ``gains``, the
    columns one after another in ``theta``) times the basis."""
    ng = len(gains)
    return [sum(t_ * g for t_, g in zip(theta[c * ng:(c + 1) * ng], gains)) for c in range(n_cols)]


# the spring and the damper a compensated candidate adds at its coordinate, per unit modal mass
COMPENSATION = ("compensation_stiffness_per_mass", "compensation_damping_per_mass")


def _compensated_fit(baseline: Baseline, loc: Location, cause, shp: dict, n_cols: int, X: np.ndarray,
                     target: np.ndarray, tt: float, gains: list[np.ndarray], lz: np.ndarray):
    """One shape of a compensated regression: (share explained, shape, elements, per-mass coefficients),
    the cause's elements first, then the spring and the damper; None where it fails or a physical cause
    comes out with the wrong sign."""
    try:
        theta = lstsq(X, target)
    except np.linalg.LinAlgError:
        return None
    if not np.any(theta[:n_cols * len(gains)]):
        return None
    lin = CAUSES["linear_mismatch"]
    elements = []
    for c, gain in enumerate(column_gains(theta, gains, n_cols + 2)):
        p = law_parameters(cause, shp, c) if c < n_cols else law_parameters(lin, {}, c - n_cols)
        elements.append(Element(cause.code if c < n_cols else lin.code, p, lz, gain, loc.weights))
    per_mass = [baseline.per_mass(loc, el.gain) for el in elements]
    if cause.positive and not all(pm > 0 for pm in per_mass[:n_cols]):
        return None
    return 1.0 - float(np.sum((target - X @ theta) ** 2)) / tt, shp, tuple(elements), per_mass


def compensation(c: Candidate) -> tuple[Element, ...]:
    """The spring and the damper of a compensated candidate (none for others)."""
    if c.cause == "linear_mismatch" or COMPENSATION[0] not in c.parameters:
        return ()
    return c.elements[-2:]


def one_sign(X: np.ndarray, y: np.ndarray, theta: np.ndarray, signs: np.ndarray, positive: bool) -> np.ndarray:
    """Least squares with the force acting in every mode with one sign (``signs``: per column, the sign
    of a positive modal mass; ``positive``: that sign only, else either): the unconstrained ``theta`` if
    it agrees, else the best fit over the subsets of columns left free whose solution agrees (2^(n-1) - 1
    small systems, n at most 3), all zero if none does. Fitted per mode without it, a regression could
    soften one mode and stiffen the next with one spring (independent seed 45: a contact at -258 /s^2 in
    the beam's mode, +0.5 in the other), which no force at one place does. The first column, the
    location's dominant mode where a candidate's coefficient is read, is in every subset: without it a
    candidate would report zero while acting in weaker modes."""
    def agrees(th):
        s = th * signs
        return bool(np.all(s >= 0) or (not positive and np.all(s <= 0)))

    if agrees(theta):
        return theta
    best, best_err = np.zeros_like(theta), float(y @ y)
    n = theta.size
    for mask in range(1, 2**n - 1, 2):
        idx = [j for j in range(n) if mask >> j & 1]
        th = np.zeros_like(theta)
        th[idx] = lstsq(X[:, idx], y)
        if agrees(th):
            err = float(np.sum((y - X @ th) ** 2))
            if err < best_err:
                best, best_err = th, err
    return best


def _parameters(cause: str, shp: dict, per_mass: list[float]) -> dict:
    c = CAUSES[cause]
    out = {p.name: float(v) for p, v in zip(c.coefficients, per_mass)}
    for p in c.shape:
        out[p.name] = shp[p.name] if p.name == "side" else float(shp[p.name])
    return out


PHYSICAL_NAMES = {"contact": ("stiffness_n_per_m",), "cubic_stiffness": ("coefficient_n_per_m3",),
                  "quadratic_stiffness": ("coefficient_n_per_m2",), "coulomb_friction": ("force_n",),
                  "quadratic_damping": ("coefficient_n_s2_per_m2",), "hysteretic_joint": ("stiffness_n_per_m",),
                  "linear_mismatch": ("stiffness_n_per_m", "damping_n_s_per_m")}


def _physical(baseline: Baseline, loc: Location, cause: str, shp: dict, elements) -> dict:
    mass = baseline.physical(loc)
    if mass is None or cause not in PHYSICAL_NAMES:
        return {}
    out = {name: float(baseline.per_mass(loc, el.gain) * mass) for name, el in zip(PHYSICAL_NAMES[cause], elements)}
    out["modal_mass_kg"] = float(mass)
    return out


def clipped_ranges(responses, share: float = 0.002) -> list[float | None]:
    """Per response (samples as recorded), its extreme value where its samples pile up there (``share`` of
    them or more: the sensor's full scale, reached), else None."""
    out = []
    for x in responses:
        a = np.abs(np.asarray(x, float))
        top = float(np.max(a))
        out.append(top if top > 0 and np.mean(a >= top * (1 - 1e-6)) >= share else None)
    return out


def clipping_candidates(prep: Prepared, ranges: list[float | None]) -> list[Candidate]:
    """A clipping at every response ``clipped_ranges`` found clipped. The ranges are read off the record as
    recorded: a record decimated to fit the memory budget has its flat tops smoothed, but clipped at the
    same range."""
    return [Candidate("clipping", name, {"range": top}, output=((i, "clip", top),))
            for i, (name, top) in enumerate(zip(prep.names, ranges)) if top is not None]


def offset_findings(prep: Prepared, raw: np.ndarray, split: Split, piece: int, settings: Settings) -> list[Candidate]:
    """Sensor offsets, judged on the record alone: a structure that stays where it is has zero mean
    acceleration and velocity, so an accelerometer or a velocity sensor whose held-out pieces all read a
    mean of the same sign (one-sided t-test against zero, p < ``alpha``) worth more than 2 % of its RMS is
    offset. The band-pass removes an offset from everything else, so it spoils no other finding."""
    out = []
    for i, (name, kind) in enumerate(zip(prep.names, prep.kinds)):
        if kind == "displacement":
            continue
        means = np.array([float(np.mean(part)) for seg in split.test
                          for part in np.array_split(raw[seg, i], max(1, (seg.stop - seg.start) // piece))])
        o = float(np.mean(raw[split.rows("train"), i]))
        rms = float(np.sqrt(np.mean(raw[:, i] ** 2)))
        if means.size < 3 or abs(o) < 0.02 * rms:
            continue
        p = paired_p(np.abs(means), np.abs(means - o))
        if p < settings.alpha:
            base = float(np.mean(np.abs(means)))
            out.append(Candidate("sensor_offset", name, {"offset": o}, output=((i, "offset", o),),
                                 block_errors=np.abs(means - o) / rms, test_nrmse=float(np.mean(np.abs(means - o)))
                                 / rms, gain=1.0 - float(np.mean(np.abs(means - o))) / base, p_value=p))
    return out


def gain_candidates(baseline: Baseline, prep: Prepared, split: Split, warm: int) -> list[Candidate]:
    """A sensor reading high or low: the least-squares scale of the baseline's prediction on training."""
    out = []
    pred = np.concatenate([predict(baseline, baseline.model, prep, s, warm) for s in split.train])
    meas = prep.measured[split.rows("train")]
    for i, name in enumerate(prep.names):
        p, m = pred[:, i], meas[:, i]
        g = float(p @ m / max(p @ p, 1e-300)) - 1.0
        out.append(Candidate("sensor_gain", name, {"gain_error": g}, output=((i, "gain", g),)))
    return out


# --- refinement ---------------------------------------------------------------------------------------


def busiest(prep: Prepared, split: Split, loc_weights: np.ndarray, count: int) -> tuple[slice, ...]:
    """The ``count`` training blocks where the location moves most, the busiest first."""
    z = prep.zva[0] @ loc_weights
    segs = split.train
    energy = [float(np.mean(z[s] ** 2)) for s in segs]
    return tuple(segs[k] for k in np.argsort(energy)[::-1][:count])


def train_error(baseline: Baseline, c: Candidate, prep: Prepared, segs, warm: int, scale, bound) -> float:
    own = c.baseline or baseline
    try:
        _, e = block_errors(own, own.model.with_elements(c.elements), prep, segs, warm, scale, c.output, bound)
    except NUMERIC_FAILURES:
        return np.inf
    return e


def _scaled(c: Candidate, baseline: Baseline, loc: Location, x: np.ndarray, shape: dict) -> Candidate:
    """The candidate with each element's gain scaled by exp(x_e) and the given shape parameters (the
    cause's elements; a compensated candidate's spring and damper keep their laws, their gains scaled too)."""
    cause = CAUSES[c.cause]
    n = len(c.elements) - len(compensation(c))
    els = []
    for e, el in enumerate(c.elements):
        p = law_parameters(cause, shape, e) if cause.shape and e < n else el.p
        els.append(Element(el.code, p, el.lz, el.gain * float(np.exp(x[e])), el.weights))
    per_mass = [baseline.per_mass(loc, el.gain) for el in els]
    shp = {p.name: shape[p.name] for p in cause.shape}
    params = _parameters(c.cause, shp, per_mass[:n]) | dict(zip(COMPENSATION, per_mass[n:]))
    return replace(c, elements=tuple(els), parameters=params, physical=_physical(baseline, loc, c.cause, shp, els[:n]))


def joint_refit(c: Candidate, baseline: Baseline, loc: Location, prep: Prepared, split: Split, warm: int,
                scale: np.ndarray, rounds: int = 2) -> Candidate:
    """A baseline fitted to the data absorbed part of a nonlinearity (a stopper raises the apparent
    frequency): fit its linear part again with the candidate's force in place (evaluated on the measured
    coordinate, the principle of nonlinear subspace identification), regress the cause again against the
    new linear part, and repeat. The candidate then carries its own baseline."""
    own = baseline
    for _ in range(rounds):
        refit = own.refit(prep, split.train, c.elements)
        if refit is own:
            break
        rows = split.rows("train")
        res = baseline_residual(refit, prep, split, warm)
        rows = rows[np.all(np.isfinite(res[rows]), axis=1)]
        again = regress(refit, prep, rows, res, loc, c.cause, scale)
        if again is None:
            break
        own, c = refit, replace(again, baseline=refit)
    return c


def _strong_starts(c: Candidate, baseline: Baseline, loc: Location, prep: Prepared, split: Split, segs, warm: int,
                   scale: np.ndarray, bound: float, err: float) -> tuple[Candidate, float]:
    """A cause fitted jointly with the linear part from its own regression, or from a strong cause.

    A linear part fitted to the record holds the cause's equivalent stiffness or damping at the record's
    average amplitude, so the regressed cause is weak and the alternation of ``joint_refit`` keeps it
    weak: a fixed point. Started from a cause worth a share of the location's modal stiffness or damping
    (the catalogue's ``starts``, ``equivalent_coefficient``), the linear part is refitted stiffer or less
    damped and the regression then finds a cause of that order. Independent seed 85, a joint: 86 /s^2
    from the regression, 1,094 /s^2 after a stiff start and the refinement, where the generator's joint
    loses 690; held-out gain 0.15 -> 0.31. Seed 94, drag: 0.1 /m from the regression, "nothing found";
    from the starts 43.5 /m where the generator has 43.6, gain 0.10. The start whose result simulates the
    busiest training blocks (``segs``) best is kept; ``err`` is ``c``'s error there. Returns the kept
    version and its error."""
    cause = CAUSES[c.cause]
    k0 = float(c.parameters.get(cause.coefficients[0].name, 0.0))
    if not cause.starts or not k0 > 0:
        return c, err
    poles = baseline.model.poles
    pole = poles[dominant_mode(baseline.coordinate_modes(loc), poles)]
    omega, zeta = float(abs(pole)), float(-pole.real / abs(pole))
    v_rms = float(np.sqrt(np.mean(loc.coordinate(prep)[1][split.rows("train")] ** 2)))
    shape = {p.name: c.parameters[p.name] for p in cause.shape}
    best = (err, c)
    for level in cause.starts:
        target = equivalent_coefficient(cause, level, omega, zeta, v_rms)
        if not (target > 0 and np.isfinite(target)):
            continue
        x = np.full(len(c.elements), np.log(target / k0))
        start = replace(_scaled(c, c.baseline or baseline, loc, x, shape), baseline=None)
        try:
            again = joint_refit(start, baseline, loc, prep, split, warm, scale)
        except NUMERIC_FAILURES:
            continue
        if again.baseline is None:
            continue
        e = train_error(baseline, again, prep, segs, warm, scale, bound)
        if e < best[0]:
            best = (e, again)
    return best[1], best[0]


@dataclass(frozen=True)
class FitLevel:
    """A separate record the baseline was fitted to (a low level): the segments it was fitted on, its split
    (a refinement simulates its busiest training blocks; its held-out blocks stay for the check), and the
    samples simulated before a block there."""
    prep: Prepared
    segments: tuple[slice, ...]
    split: Split
    warm: int


def refine(c: Candidate, baseline: Baseline, loc: Location, prep: Prepared, split: Split, warm: int,
           scale: np.ndarray, bound: float, settings: Settings, joint: bool = True,
           fit: FitLevel | None = None) -> Candidate:
    """Refine a mechanical candidate by simulation error on the busiest training blocks: a baseline fitted
    to this record is first refitted jointly with it (``joint_refit``, if ``joint``; a joint, a drag or a
    dry friction or a stopper also from strong starts, ``_strong_starts``); a baseline fitted
    to a separate record (``fit``: its preparation and segments, a low level) is refitted there with the
    candidate in place, before and after the refinement (the cause acts at the low level too: the linear
    part fitted there without it holds the cause's equivalent stiffness and damping twice, and every version
    tried must simulate that record's busiest training blocks within the gain floor of the baseline:
    the refinement searches among versions that hold at both levels); then its
    coefficients are scaled (log, within a factor e^2, e^5 for a joint's stiffness and at least that for a
    stopper's, whose scan reaches 100 times the fastest mode's stiffness); a
    contact's side, gap and stiffness are scanned first (a stiff stopper's error is a narrow valley in
    the gap), a joint's slip displacement is scaled too. A compensated candidate (``regressions``) is refined
    with ``joint=False``: its spring and damper are scaled with the cause and keep their laws, and a stiffness
    level of the scans lifts the cause alone."""
    if not c.elements:
        return c
    base0 = baseline
    at_fit = _at_fit_level(fit, loc, base0, settings)
    if fit is not None:
        c = _refit_at(fit, base0, c, at_fit)
    elif joint and c.baseline is None:
        c = joint_refit(c, baseline, loc, prep, split, warm, scale)
    segs = busiest(prep, split, loc.weights, settings.refine_blocks)
    base_err = train_error(base0, c, prep, segs, warm, scale, bound)  # c's own linear part where it has one
    if joint and fit is None:
        c, base_err = _strong_starts(c, base0, loc, prep, split, segs, warm, scale, bound, base_err)
    baseline = c.baseline or baseline
    cause = CAUSES[c.cause]
    shape0 = {p.name: c.parameters[p.name] for p in cause.shape}
    n_el = len(c.elements)
    n_cause = n_el - len(compensation(c))  # a compensated candidate's spring and damper come last

    def lifted(lk: float) -> np.ndarray:
        """A contact's or a joint's stiffness level for the cause's elements (its spring and damper stay)."""
        x = np.zeros(n_el)
        x[:n_cause] = lk
        return x

    # how far a coefficient may move (log): a stopper's stiffness is uncertain by orders of magnitude
    # (displacement integrated from accelerations is smoothed over millisecond contacts), others are not
    reach = 5.0 if cause.code in (CONTACT, JOINT) else 2.0

    def holds(cand: Candidate) -> bool:
        return at_fit.error(cand) <= at_fit.limit

    def run(x, shape):
        if np.max(np.abs(x[:n_el])) > reach:
            return np.inf, None
        cand = _scaled(c, baseline, loc, x, shape)
        if not holds(cand):
            return np.inf, None
        return train_error(baseline, cand, prep, segs, warm, scale, bound), cand

    best = (base_err, c)
    grid = []  # (shape, log stiffness factor) tried on the two busiest blocks before the simplex
    if cause.code == CONTACT:
        # scan side, gap and stiffness: the regression sees displacement smoothed by the band, so it finds a
        # soft stopper at a smaller gap; a stiff one at the true gap fits the simulation as well, and only a
        # scan that tries stiff stoppers finds it
        gap0 = float(shape0["gap"])
        w2 = float(np.max(np.abs(baseline.model.poles)) ** 2)
        k0 = max(c.parameters["stiffness_per_mass"], 1e-300)
        levels = sorted({0.0} | {max(float(np.log(f * w2 / k0)), -reach) for f in (10.0, 100.0)})
        # the stiff levels are absolute (10 and 100 times the fastest mode's stiffness per mass), not a
        # factor of the regression's value: a regression a thousand times too soft had kept the scan and
        # the simplex below e^5 of it (independent seed 67: 1.7e4 /s^2 where the stopper has 2.4e5)
        reach = max(reach, max(levels) + 1.0)
        grid = [({"gap": gap0 * fct, "side": side}, lk)
                for side in SIDES for fct in np.linspace(0.6, 1.6, 11) for lk in levels]
    elif cause.code == JOINT:
        # scan the slip onset with the slip and stiffness: the regression sees a joint slipping from rest,
        # a preloaded one slips only near the largest motion, and a residual regression cannot tell the
        # two apart (its best fit of a late onset is a force that destabilises the simulation)
        slip0 = float(shape0["slip"])
        grid = [({"slip": slip0 * fct, "onset": onset}, lk)
                for onset in ONSETS for fct in (0.5, 1.0, 2.0, 4.0) for lk in (0.0, 1.0, 2.0)]
    starts = [(shape0, 0.0)]
    if grid:
        versions = [_scaled(c, baseline, loc, lifted(lk), shp) for shp, lk in grid]
        scan = sorted((train_error(baseline, v, prep, segs[:2], warm, scale, bound), i)
                      for i, v in enumerate(versions) if holds(v))
        starts = [grid[i] for _, i in scan[:2]] or starts
    for shp, lk in starts:
        free = [k for k in ("gap", "slip") if k in shp]

        def err(x, shp=shp, free=free):
            shape = dict(shp)
            for k, xi in zip(free, x[n_el:]):
                if abs(xi) > 0.7:
                    return np.inf, None
                shape[k] = shp[k] * float(np.exp(xi))
            return run(x, shape)

        x0 = np.zeros(n_el + len(free))
        x0[:n_el] = lifted(lk)
        step = np.full(x0.size, 0.05)  # a gap or a slip is known from the scan within a few per cent
        step[:n_el] = 1.0 if reach > 2 else 0.3
        simplex = np.vstack([x0, x0 + np.diag(step)])
        try:
            res = minimize(lambda x: min(err(x)[0], PENALTY), x0, method="Nelder-Mead",
                           options={"maxfev": settings.refine_evals // len(starts), "xatol": 1e-3,
                                    "fatol": 1e-5, "initial_simplex": simplex})
        except NUMERIC_FAILURES as exc:
            return replace(c, note=f"refinement failed: {exc}")
        e, cand = err(res.x)
        if cand is not None and e < best[0]:
            best = (e, cand)
    e, cand = best
    if fit is not None:
        again = _refit_at(fit, base0, cand, at_fit)
        if again is not cand:
            cand, e = again, train_error(base0, again, prep, segs, warm, scale, bound)
    return replace(cand, refined=True, train_nrmse=e)


@dataclass(frozen=True)
class AtFitLevel:
    """A candidate's simulation error on the fit record's busiest training blocks at its location
    (``error``; on its own linear part, else the baseline's), and the most it may be: the baseline's
    there plus the gain floor (``limit``; infinite without a fit record)."""
    error: Callable[[Candidate], float]
    limit: float


def _at_fit_level(fit: FitLevel | None, loc: Location, base0: Baseline, settings: Settings) -> AtFitLevel:
    """The refinement's rule at the fit record's level: every version it tries must simulate that record's
    busiest training blocks no worse than the baseline ``base0`` there, within the gain floor (the check the
    selection makes on that record's held-out blocks, applied while refining, so that a cause acting at
    both levels is estimated from both: the F-16's joint at Acceleration2, refined on level 7 alone,
    slipped at level 1 and predicted it 34 % worse)."""
    if fit is None:
        return AtFitLevel(lambda cand: 0.0, np.inf)
    busy = busiest(fit.prep, fit.split, loc.weights, settings.refine_blocks)
    scale_f = np.maximum(fit.prep.measured[rows_of(busy)].std(axis=0), 1e-300)
    bound_f = simulation_bound(fit.prep)
    _, e0 = block_errors(base0, base0.model, fit.prep, busy, fit.warm, scale_f, (), bound_f)
    return AtFitLevel(lambda cand: train_error(base0, cand, fit.prep, busy, fit.warm, scale_f, bound_f),
                      (1.0 + settings.gain_floor) * e0)


def _refit_at(fit: FitLevel, base0: Baseline, cand: Candidate, at_fit: AtFitLevel) -> Candidate:
    """The candidate with the baseline's linear part refitted on the fit record with its elements in place,
    if that simulates the fit record better than the linear part it has: the refit's purpose is the fit
    record (the linear part fitted there without the cause holds its equivalent stiffness and damping
    twice), and it fits the elements' force on the measured coordinate, not their simulation, so it can
    miss (the F-16's joint between sensors 2 and 3: its refit made level 1's held-out blocks 18 % worse,
    0.104 -> 0.123)."""
    again = replace(cand, baseline=base0.refit(fit.prep, fit.segments, cand.elements))
    return again if at_fit.error(again) < at_fit.error(cand) else cand


# --- selection ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Selection:
    findings: list[Candidate]
    ambiguous: list[list[Candidate]]  # per finding: the look-alikes the data cannot separate from it
    reasons: list[str]


def over_own_part(c: Candidate, floor: float, alpha: float) -> bool:
    """Does a candidate refitted with its own linear part beat that part alone on the held-out blocks (true
    where it has none: nothing to ask)? By more than the gain floor, and, unless the cause acts in a few
    pieces by nature (``Cause.intermittent``, a stopper), in the typical piece: the signed-rank test over
    the pieces (``own_p``) at ``alpha``, the test a cause meets against the baseline.

    A few pieces much better carry a mean gain over the floor while most pieces are worse: that gain is
    the refit's, not the cause's (independent seed 389, a joint at tip 2: a cubic there 15 % better than
    its own part on average, p = 0.77 piece by piece, made the answer "ambiguous: cubic or joint"; 428
    and 441 likewise). A stopper's gain lives in the pieces where it touches, and the typical piece does
    not show it (seeds 81 and 92, true contacts, own gains 0.06 and 0.33 at p = 0.20 and 0.14). Measured
    whole (stop 75): seeds 0-99 unchanged (75 / 90 / 0), 300-399 +1 named right, 400-499 +2 and two
    false extra findings fewer; asking stoppers too lost 81 and 92."""
    if np.isnan(c.own_gain):
        return True
    if c.own_gain <= floor:
        return False
    return CAUSES[c.cause].intermittent or not c.own_p >= alpha


def significant(c: Candidate, settings: Settings) -> bool:
    """Does a scored candidate beat the baseline: below predicting zero, by more than the gain floor, by
    the paired test, and over its own linear part alone (``over_own_part``: by the gain floor, in the
    typical piece unless it is a stopper), or, where it does not on held-out blocks, by ``ACTS_IN_TRAINING``
    over the training blocks (``_own_gain_trained``)?

    A compensated candidate (``regressions``) must also gain more over its own spring and damper than the
    whole of it gains over the baseline: ``own_gain < gain`` is the same as "the spring and the damper
    alone predict better than the baseline". Where they are the equivalent linearisation of a true cause
    taken out of a fitted linear part, alone they undo that part and predict worse (independent seeds 18,
    a Coulomb friction, and 89, a drag: 2.5 and 2.7 x the baseline's held-out NRMSE); where they improve on
    the baseline, the fitted linear part was simply off (a linear mismatch is no finding against a model
    fitted to the same record, ``discover.findable``), and the cause rides on top of a linear correction
    (the softening family's seed 17, nothing hidden: the spring and damper alone 0.0512 against the
    baseline's 0.0549, a Coulomb friction on top 0.0485, named at p = 6e-39 before this rule)."""
    return beats_baseline(c, settings) and (over_own_part(c, settings.gain_floor, settings.alpha)
                                            or c.own_gain_trained >= ACTS_IN_TRAINING)


def beats_baseline(c: Candidate, settings: Settings) -> bool:
    """``significant`` without the test over the candidate's own linear part: below predicting zero, by the
    gain floor and the paired test over the baseline, and, compensated, better than its spring and damper."""
    return (np.isfinite(c.test_nrmse) and c.test_nrmse < 1.0 and c.gain > settings.gain_floor
            and c.p_value < settings.alpha and not (compensation(c) and c.own_gain < c.gain))


def beats(a: Candidate, b: Candidate, settings: Settings) -> bool:
    """Does ``a`` predict the held-out blocks significantly better than ``b``?"""
    return paired_p(b.block_errors, a.block_errors) < settings.alpha


def displaces(a: Candidate, b: Candidate, settings: Settings) -> bool:
    """May the more complex ``a`` set the simpler ``b`` aside? Only by beating it significantly and by
    the share a finding must cut off the baseline (``gain_floor``). Over a record's held-out pieces a
    paired test calls a sliver significant: on the rig generator a linear mismatch (two numbers) beat the
    true sensor gain (one) by 0.7 to 2.2 % of its held-out error over 32 pieces (p = 0.0003-0.016), and was
    named instead of it (seeds 32, 53, 84; seed 61's, 5.6 % better, still is); at one drive frequency the
    two are the same complex ratio."""
    return beats(a, b, settings) and a.test_nrmse < (1.0 - settings.gain_floor) * b.test_nrmse


def choose(cands: list[Candidate], settings: Settings) -> tuple[Candidate | None, list[Candidate], str]:
    """The first finding among candidates: the best significant one that displaces every simpler
    significant one (``displaces``: else that simpler one, recursively); the significant others it does
    not beat are its look-alikes, except a more complex one that predicts the held-out blocks no better
    (``dominated``)."""
    sig = sorted([c for c in cands if significant(c, settings)], key=lambda c: -c.gain)
    if not sig:
        return None, [], "no cause beats the baseline significantly on held-out blocks"
    best = sig[0]
    while True:
        simpler = [c for c in sig if c.order < best.order and not displaces(best, c, settings)]
        if not simpler:
            break
        best = max(simpler, key=lambda c: c.gain)
    # a look-alike of the same cause between the same sensors (their difference or their sum, whichever
    # way the signs fell) says the same thing; at another place it is another answer: a stopper between
    # masses 1 and 2 is not one from mass 1 to the ground (independent seed 17, a chain: a contact named
    # between a1 and a2 alone, where one at a1 predicted as well)
    alike = [c for c in sig if c is not best and not beats(best, c, settings) and not dominated(c, best)
             and not (c.cause == best.cause and same_sensors(c.location, best.location))]
    return best, alike, ""


def dominated(c: Candidate, best: Candidate) -> bool:
    """Is ``c`` more complex than the finding ``best`` and no better on the held-out blocks? Then it is no
    rival answer: a cause with more fitted numbers that predicts no better than a simpler one explains
    nothing the simpler one does not, and it could never displace it (``displaces``). On the rig
    generator a true sensor gain (one number) was reported "ambiguous" with a linear mismatch (two) that
    predicted 0.5 % worse (seed 4, held-out gains 0.750 and 0.746); on the independent generator a true
    cubic with a contact that predicted 27 % worse (seed 51, a hammer record whose few blocks left the
    paired test short). A more complex look-alike that predicts better, however slightly, stays one."""
    return c.order > best.order and c.test_nrmse >= best.test_nrmse


def same_sensors(a: str, b: str) -> bool:
    """Do two locations name the same sensors ("a2-a3", "a3+a2")?"""
    split = lambda s: frozenset(s.replace("+", "-").split("-"))  # noqa: E731
    return split(a) == split(b)
