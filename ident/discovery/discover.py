"""``discover``: the one entry point. Measured data in, a ``Discovery`` out.

    Measurement ──prepare──> Prepared (band, signs, kinematics)
         │                      │
         │          baseline: RigBaseline(config) | ModalBaseline.fit(training or fit data),
         │                    its order chosen in the preliminary band, then again in the modes' band
         │                      │
         └── split (interleaved blocks) ── baseline scored per held-out block ── transients left out
                                │
         characterise (restoring-force curves per location) ── regress every cause at every location
                                │
         refine each cause's best location by simulation (a fitted baseline with more modes than responses:
                                │                          regress and refine again on fewer, ``_fewer_modes``;
                                │                          with fewer, on one more, ``_one_more_mode``)
         score on held-out blocks ── select
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
from threadpoolctl import threadpool_limits

from ..rig import RigParams
from .backbone import free_decay
from .baselines import Baseline
from .baselines.modal import (ModalBaseline, band_lines, check_errors, decay_rows, drivable, glide_partners, gliding,
                             peak_poles, structural, vector_fit_poles)
from .baselines.rig import RigBaseline
from .catalogue import CAUSES, describing_stiffness
from .characterise import characterise
from .model import NUMERIC_FAILURES
from .result import Discovery, options, softens
from .search import (Candidate, FitLevel, Scoring, Selection, Settings, baseline_residual, beats_baseline,
                     block_errors, busiest, choose, clipped_ranges, clipping_candidates, clustered_p, compensation,
                     gain_candidates, moving_pieces, offset_findings, paired_p, pieces_per_block, predict, refine,
                     regress, regressions, same_sensors, score, significant, simulation_bound, spring_damper_responses,
                     train_error)
from .signals import (HARMONICS, HIT_RESPONSE, ORDER, UNDRIVEN_SHARE, Channel, Dropout, Measurement, Prepared, above_band,
                      below_band, convert, dropouts, first_family, impulsive, modal_band, preliminary_band, prepare,
                      span_text, undriven, within_budget)
from .split import Split, blocks_reached, by_energy, given, interleaved, resonant_block, rows_of, transients


PIECE_PERIODS = 5  # periods of the slowest mode per piece of the paired test
QUIET_CHECK = 0.97  # held-back blocks no model predicts better than this share of zero's error hold no response
CLEARLY_BETTER = 0.95  # a regression simulating the training blocks within 95 % of the baseline's error
BLOCK_PERIODS = 4.0  # periods of the slowest mode per block (the band's low edge is 0.4 x that mode)
# a fitted baseline's band reaches this many times its highest mode, not ``HARMONICS``, where responses carry
# motion the input does not drive above the usual band (``signals.above_band``): a stiff stopper's impacts
# ring there, and a search in the narrower band misses the stopper. On the independent generator's 34 contacts
# so noted among seeds 0-999 (stop 86, README): right 12 -> 13, wrong answers 6 -> 4, false extras 7 -> 5
WIDE_HARMONICS = 10.0
WHAT_DROPS = "a dropout (a loose connector, a lost sensor, a stalled converter, lost packets)"


def _warm(baseline: Baseline, prep: Prepared) -> int:
    """Samples simulated before a block, nudged towards the measured velocities: three periods of the
    slowest mode the band holds (at least the band-pass's edge).

    A pole below the band's low edge is a device of the fit (the drift of integrated accelerations), of
    which the band-passed data carry nothing; three of its periods had set the warm-up to 15 s at 0.19 Hz
    (independent seed 30) and to the whole record at 0.01 Hz (seed 5): every block was simulated from the
    record's start, and the transient detector, which looks only past the first warm-up, missed a blow at
    15.1 s. The band's low edge bounds the warm-up instead."""
    f = max(float(np.min(baseline.model.frequencies_hz)), float(prep.band[0]))
    return max(prep.edge, int(3.0 / f * prep.fs_hz))


def _fit_modal(m: Measurement, fit_data: Measurement | None, train: slice | None, test: slice | None,
               harmonics: float = HARMONICS):
    """Band from a first fit on the preliminary band, then the baseline fitted again in the modes' band.

    The first fit chooses its order on every third training block (of the whole record with ``fit_data``),
    left out of the fit; a single training slice (``--train``) leaves the choice to the fit error, and a
    hammer record whose held-back blocks are the quiet after its decay to the decay (``_order_on_the_decay``)."""
    src = fit_data or m
    prep0 = prepare(src)
    split0 = _split(prep0, None if fit_data else train, None if fit_data else test)
    rows, check = _held_back(split0.blocks if fit_data else split0.train)
    first = ModalBaseline.fit(prep0, rows, check=check)
    if check is not None and prep0.transient:
        try:
            first = _order_on_the_decay(first, prep0, rows, check)
        except NUMERIC_FAILURES:  # a fit that fails on the decay leaves the first fit as it was
            pass
    # the band is where the modes are: a pole whose decay the record cannot resolve is a sinusoid the
    # fit kept (independent seed 81: 1.44 Hz at zeta 1e-27 set the band's low edge at 0.73 Hz, where
    # the rig's first mode is 7.3 Hz), not a mode
    light = drivable(first.model.poles, prep0)
    light = light if np.any(light) else structural(first.model.poles, prep0)
    light &= ~glide_partners(first.model.poles, prep0)
    if not np.any(light):
        raise ValueError("no lightly damped mode in the data: nothing resonates in the band "
                         f"{prep0.band[0]:.3g}-{prep0.band[1]:.3g} Hz")
    # the shorter record's duration bounds the low edge (the two may be at different rates)
    n = min(m.n, src.n if src.fs_hz == m.fs_hz else int(round(src.n * m.fs_hz / src.fs_hz)))
    # a second family of modes far above the first is left out where the motion is not there (``first_family``)
    f = first.model.frequencies_hz
    light &= np.isin(f, first_family(f[light], prep0.zva[0][prep0.edge:prep0.n - prep0.edge], prep0.fs_hz))
    return modal_band(first.model.frequencies_hz[light], m.fs_hz, n, harmonics), first.model.poles[light]


def _reciprocity(baseline: ModalBaseline, prep: Prepared, rows: np.ndarray, residual: np.ndarray,
                 locations: list, scale: np.ndarray, char: dict, notes: list[str]) -> tuple[ModalBaseline, dict]:
    """The modal baseline with its reciprocity taken through the response, of those that read alike as the
    driving point (``Prepared.driving_alike``), through which a force surface at some location explains the
    most of the training residual (``characterise``), and that characterisation; the response taken by the
    signs keeps it unless another explains more. A force at a place enters mode r as lz_r / C_dr: through a
    transfer point in phase with the driven one each mode's gain is off by the ratio of their shapes, and
    nothing in a linear fit with one input tells which is driven. The choice is made on training blocks;
    the held-out blocks still judge every cause (independent seed 5, a chain pushed at its fourth mass and
    driven about its first mode, the third taken by the signs: 5.3 % of the residual explained, 6.1 %
    through the fourth, and its drag, "nothing" before, found between its second and third masses)."""
    best = (max(c["explained"] for c in char.values()), baseline, char)
    first = best[0]
    for j, sign in prep.driving_alike:
        other = baseline.through(j, sign)
        c = characterise(other, prep, rows, residual, locations, scale)
        top = max(v["explained"] for v in c.values())
        if top > best[0]:
            best = (top, other, c)
    if best[1] is not baseline:
        notes.append(f"the modal baseline's reciprocity taken through {prep.names[best[1].driving_point]}, which "
                     f"reads as a driving point as {prep.names[baseline.driving_point]} does: a force surface "
                     f"through it explains {100 * best[0]:.1f} % of the training residual, {100 * first:.1f} % "
                     f"through {prep.names[baseline.driving_point]}")
    return best[1], best[2]


def _order_on_the_decay(first: ModalBaseline, prep0: Prepared, rows: np.ndarray,
                        check: np.ndarray) -> ModalBaseline:
    """A hammer record's first fit (``first``, its order chosen on the held-back rows ``check``) again with its
    order chosen on the decay, where that choice was blind, else ``first``.

    Where the held-back blocks lie in the quiet after the decay, no order predicts them better than zero does
    (every check error at least ``QUIET_CHECK``), so they cannot choose one, and the first order was kept
    whatever the decay held. The decay chooses it instead (``fit_model``'s ``decay``). The preliminary band's
    low edge makes a long band-pass edge, which can hold the whole decay (independent seed 158, a
    clamped-clamped beam hit at 4.5 ms: an edge of 0.54 s, every check error 1.00, one mode of two found, the
    band set above the other): a record at rest before its hit has no start transient to wait out, and its
    decay is taken from the hit on. Only then: a hardening decay's loud start is its stiffest part, and the
    fit it leads is the stiffer (seed 4: 166.6 Hz from the hit on, 160.8 Hz after the edge, the beam's
    160.7). The decay's fit replaces the first where it chose another order; where it chose the same, the
    first stands (seed 106's two differed in round-off, and its cubic, found on the first, was "ambiguous")."""
    if not np.all(check_errors(first.model.poles, prep0, rows, check) >= QUIET_CHECK):
        return first
    rung, at = decay_rows(prep0, rows), rows
    if rung is None and prep0.rest_until is not None and prep0.rest_until < rows[0]:
        at = np.concatenate([np.arange(prep0.rest_until, rows[0]), rows])
        rung = decay_rows(prep0, at)
    if rung is None:
        return first
    decayed = ModalBaseline.fit(prep0, at, decay=rung)
    return decayed if decayed.model.poles.size != first.model.poles.size else first


def _left_out(segs: list[slice]) -> tuple[list[slice], list[slice]]:
    """The blocks a modal fit is fitted on and those its choices are checked on: every third block held
    back (none with fewer than three blocks)."""
    check = segs[2::3] if len(segs) >= 3 else []
    return [s for s in segs if s not in check], check


def _held_back(segs: list[slice]) -> tuple[np.ndarray, np.ndarray | None]:
    """``_left_out``'s blocks as rows (None for the check with fewer than three blocks, where the fit error
    chooses the order)."""
    fit, check = _left_out(segs)
    return rows_of(fit), (rows_of(check) if check else None)


def _fit_in_band(prep: Prepared, split: Split, poles0: np.ndarray) -> ModalBaseline:
    """The baseline in the modes' band, fitted on the training blocks from the first fit's poles, or from
    the poles of the order chosen again in this band (every third training block left out to choose it)
    when that model predicts every response on the left-out blocks better than zero does and with 10 %
    less error (summed over the responses) than the first fit's poles.

    The first fit's band can be ruled by other modes: a hammer's accelerations by the beams' second and
    third modes, where its order search stops at one first mode of two (independent twin 68: held out at
    0.85 with one mode, 0.13 with both). Where neither model predicts the left-out blocks (a hardening
    beam's hammer decay, independent seeds 10 and 31: both err 45-1,000 times that response) the first
    fit's order stays."""
    rows, at = _held_back(split.train)
    if at is not None:
        try:
            searched = ModalBaseline.fit(prep, rows, check=at).model.poles
            mine, theirs = check_errors(searched, prep, rows, at), check_errors(poles0, prep, rows, at)
            # nor a one-response fit that is one mode gliding, as the order's choice holds it (``gliding``):
            # a refinement after that choice can make such a pair (independent seed 93, a clamped-clamped
            # beam's hardening hammer decay: 167.2 Hz undamped, 168.6 and 169.5 Hz where the first fit had the
            # beam's mode, 166.4 Hz; the undamped line rang on through the record's quiet tail, and the
            # baseline held out 1.9 times worse than predicting zero)
            if np.all(mine < 1.0) and mine.sum() < 0.9 * theirs.sum() and not gliding(searched, prep):
                poles0 = searched
        except NUMERIC_FAILURES:
            pass
    return _without_devices(ModalBaseline.fit(prep, split.rows("train"), poles0=poles0), prep, split)


def _without_devices(fitted: ModalBaseline, prep: Prepared, split: Split) -> ModalBaseline:
    """The baseline fitted again without its overdamped poles above the band (zeta > 0.5: no mode of the
    band, a device of the fit, often pinned at the admissible 0.49 fs) when that model simulates the
    training blocks (as the held-out blocks are scored: free run from the state read off the data) with
    10 % less error than the fitted one.

    The fit minimises the error of the forced response, not of a free run: such a pole can cut the first
    and let the second wander (independent seed 53, a Coulomb friction at tip 2: a pole at 156-165 Hz at
    zeta 1, the training blocks run free at 0.45, without it 0.04; held out 0.41 and 0.09). It is the
    fitted model that is checked, on the blocks it was fitted to: an earlier check fitted both models
    again on two thirds of those blocks and ran the third, and the refit's device pole landed elsewhere
    and did not wander (seed 53 on a second host: 1,030 Hz, 0.09 against 0.11; the pole kept, held out at
    0.41). On independent seeds 0-99 (stop 55's host), six baselines have such a pole; on each the
    training blocks' free runs and the held-out blocks' agree on which model is better (seeds 13, 45, 53,
    89: 3-9 x, kept by the refit's check; 38: 0.30 against 0.48; 77: a tie). A pole the free runs need
    stays (the overdamped poles below the band, the drift of integrated accelerations they fit, are not
    touched: removing them made seeds 44, 58 and 67 worse).

    Only training blocks are scored; the warm-up before each reads the measured state before it, which
    can lie in a held-out block (as the held-out blocks' warm-ups read training data). With one given
    training slice (``--train``) the check is that slice's free run; the refit's check had needed three
    blocks and was skipped there."""
    p = fitted.model.poles
    device = (-p.real / np.abs(p) > 0.5) & (np.abs(p) / (2 * np.pi) > prep.band[1])
    if not device.any() or device.all():
        return fitted
    train = split.train
    scale = np.maximum(prep.measured[rows_of(train)].std(axis=0), 1e-300)
    bound = simulation_bound(prep)
    try:
        without = ModalBaseline.fit(prep, rows_of(train), poles0=p[~device])
        errs = [block_errors(b, b.model, prep, train, _warm(b, prep), scale, (), bound)[1] for b in (fitted, without)]
        if errs[1] < 0.9 * errs[0]:
            return without
    except NUMERIC_FAILURES:
        pass
    return fitted


def _split(prep: Prepared, train: slice | None = None, test: slice | None = None) -> Split:
    """The given train and test ranges, else interleaved blocks of at least ``BLOCK_PERIODS`` periods of
    the slowest mode (the band's low edge is 0.4 x its frequency): equal in time, or on a hammer-hit
    record equal in the motion's energy (``split.by_energy``)."""
    if train is not None or test is not None:
        n = prep.n
        # one of the two given: the other is the longer stretch of the record on either side of it (a default
        # first 60 % had overlapped a --test given at the start, and the refusal named a --train never given)
        one = train or test
        rest = max((slice(0, one.start), slice(one.stop, n)), key=lambda s: s.stop - s.start)
        return given(n, prep.edge, train or rest, test or rest)
    block_s = BLOCK_PERIODS * 0.4 / float(prep.band[0])
    min_block = max(int(block_s * prep.fs_hz), 16)
    if prep.transient:  # a hammer hit: blocks of equal shares of the motion, not of time
        scale = np.maximum(prep.measured.std(axis=0), 1e-300)
        return by_energy(np.sum((prep.measured / scale) ** 2, axis=1), prep.edge, min_block)
    split = interleaved(prep.n, prep.edge, min_block)
    # a sweep's resonance, rung in one block, is trained on where there are several responses
    # (``split.resonant_block``). With one, on the independent Duffing oscillator's sweeps, it cost the
    # hardening seed 907 its cubic (the jump's block trained on, the cubic acting there alone) and gave the
    # softening family's seed 17, nothing hidden, a Coulomb friction; its one mode was fitted either way
    loud = resonant_block(prep.measured, split) if len(prep.names) > 1 else None
    if loud is not None and loud in split.held_out:
        split = interleaved(prep.n, prep.edge, min_block, trained=loud)
    return split


def discover(m: Measurement, *, rig: RigParams | None = None, fit_data: Measurement | None = None,
             train: slice | None = None, test: slice | None = None, settings: Settings = Settings(),
             progress: Callable[[str], None] | None = None) -> Discovery:
    """What the baseline (the rig model ``rig``, or a modal model fitted to the data or to ``fit_data``)
    gets wrong in ``m``, its cause, and the gain of the extended model on held-out blocks.

    ``progress``, if given, is called with one line at each stage (the baseline, the search's size, each
    refinement, the scoring): a record with many sensors takes minutes, and a person at a terminal should
    see which stage it is in (``ident discover`` prints them there).

    The linear algebra runs on one BLAS thread: the fits and the refinements follow round-off, so with
    several threads the same record could give another answer (independent seed 73: a cubic with one
    thread, nothing with two); with one, ``ident discover``, the tests and the benchmark's Dask tasks
    agree."""
    if rig is not None:  # (checked first: the model's matrices had met the record's as numpy's shape error)
        if len(m.responses) != 2:
            raise ValueError(f"the rig model has two tips: give their two responses (tip 1's, then tip 2's), got "
                             f"{len(m.responses)}")
        if m.excitation.kind != "base_acceleration":
            raise ValueError(f"the rig model is driven by its base's acceleration; the excitation "
                             f"{m.excitation.name!r} is a {m.excitation.kind.replace('_', ' ')}: give it as "
                             "base_acceleration, or leave --model out for a model fitted to the data")
    with threadpool_limits(limits=1, user_api="blas"):
        band0 = preliminary_band(m)
        m, fit_data, input_notes = _undriven_left_out(m, fit_data, band0, keep=rig is not None)
        ranges = clipped_ranges(ch.values for ch in m.responses)  # as recorded, before any decimation
        # (found as recorded: decimated, a run is no longer one value)
        gaps = _gaps(m, band0, input_notes)
        fit_gaps = [] if fit_data is None else _gaps(fit_data, preliminary_band(fit_data), input_notes, "fit data: ")
        input_notes += _input_clipped(m.excitation)
        m, fit_data, train, test, notes = _within_budget(m, fit_data, train, test, settings.max_samples)
        try:
            return _discover(m, rig, fit_data, train, test, settings, progress or (lambda line: None), notes,
                             ranges, input_notes, gaps, fit_gaps)
        except ValueError as exc:
            if not notes or type(exc) is not ValueError or not str(exc):
                raise
            raise ValueError(f"{exc} (after {'; '.join(notes)})") from exc


def _undriven_left_out(m: Measurement, fit_data: Measurement | None, band: tuple[float, float], keep: bool
                       ) -> tuple[Measurement, Measurement | None, list[str]]:
    """The record (and ``fit_data``) without the responses that carry nothing the input drives
    (``signals.undriven``: a dead, unplugged or disconnected sensor), and the note that says so. Left in,
    such a response is one more the baseline must fit, and it fits its noise: independent seed 75 (a contact
    at tip 2) with tip 2 read as a constant and noise gave a baseline held out 7.7 times worse than zero and
    a confident false finding at tip 1 (quadratic stiffness, gain 0.90). Where every response is so, or the
    baseline is the rig model (``keep``: it needs both tips), the responses stay and the note says what the
    record holds."""
    dead = undriven(m, band)
    if not dead:
        return m, fit_data, []
    if impulsive(m.excitation.values):
        named = ", ".join(f"{m.responses[i].name}'s at {r:.2g} times" for i, r in dead)
        why = (f"the hits of {m.excitation.name} leave no ringing: the mean square after a hit stands at most "
               f"{named} its level before it, where a response the hits drive stands at {HIT_RESPONSE:g} times "
               "or more")
    else:
        named = ", ".join(f"{m.responses[i].name} {100 * s:.0f} %" for i, s in dead)
        why = (f"the share of the power in the band coherent with the input {m.excitation.name} is {named}, where "
               f"a response the input drives has {100 * UNDRIVEN_SHARE[16]:.0f} % or more")
    if len(dead) == len(m.responses):
        return m, fit_data, [f"no response is driven by the input: {why}; is {m.excitation.name} the "
                             "channel that drove the structure, and are the sensors live? Every gain here is "
                             "measured against a baseline of what the input does not make"]
    if keep:
        return m, fit_data, [f"{why}: a dead, unplugged or disconnected sensor? The rig model needs both "
                             "tips, so it stays in the analysis"]
    gone = {m.responses[i].name for i, _ in dead}

    def without(x: Measurement) -> Measurement:
        return replace(x, responses=tuple(ch for ch in x.responses if ch.name not in gone),
                       lost=tuple(g for g in x.lost if g.name not in gone))

    m = without(m)
    if fit_data is not None and any(ch.name not in gone for ch in fit_data.responses):
        fit_data = without(fit_data)
    return m, fit_data, [f"left out {', '.join(sorted(gone))}: {why}; a dead, unplugged or disconnected sensor?"]


SHORT_GAP = 0.1  # of a period of the band's top: a missing run shorter than this is bridged, not left out


def _gaps(m: Measurement, band: tuple[float, float], notes: list[str], what: str = "") -> list[Dropout]:
    """The record's dropouts (``signals.dropouts``) and its runs of missing samples (``Measurement.lost``)
    long enough to leave out; a note on the shorter ones, which stay bridged: over a tenth of a period of
    the band's top, linear interpolation errs by at most (pi / 10)^2 / 2 = 5 % of a sinusoid's amplitude,
    for a few samples. A recording that lost 1 % of its frames one by one (the simulated rig's fault) had
    every block reached, and was told to cut the record."""
    short = SHORT_GAP / band[1]
    brief = [g for g in m.lost if g.stop_s - g.start_s < short]
    if brief:
        longest = max(g.stop_s - g.start_s for g in brief)
        runs = len({(g.start_s, g.stop_s) for g in brief})  # (a row missing in several channels is one run)
        notes.append(f"{what}{runs} short run{'s' if runs > 1 else ''} of missing samples bridged by "
                     f"interpolation (the longest {1e3 * longest:.3g} ms, under a tenth of a period at "
                     f"{band[1]:.3g} Hz, the top of the band first estimated from the record) and analysed")
    return [g for g in m.lost if g.stop_s - g.start_s >= short] + dropouts(m, band)


def _said(gaps: list[Dropout], most: int = 4) -> str:
    """The dropouts in words, in the order of time: a run that several channels share (a lost frame; the
    F-16's sine sweeps end with Acceleration2 and 3 both at 0) named once, and beyond ``most`` runs their
    count and the first of them."""
    runs: dict[tuple, list[str]] = {}
    for g in gaps:
        runs.setdefault((g.start_s, g.stop_s, "nan" if np.isnan(g.value) else g.value), []).append(g.name)
    words = []
    for (a, b, value), names in sorted(runs.items(), key=lambda r: r[0][:2]):
        many = len(names) > 1
        if value == "nan":
            words.append(f"{', '.join(names)} hold{'' if many else 's'} no number {span_text(a, b)} (bridged by "
                         "interpolation)")
        else:
            words.append(f"{', '.join(names)} read{'' if many else 's'} {value:.4g} {span_text(a, b)} while the "
                         "excitation moves")
    if len(words) > most:
        return f"{len(words)} runs, the first: " + "; ".join(words[:2])
    return "; ".join(words)


def _without_dropouts(split: Split, prep: Prepared, gaps: list[Dropout]) -> tuple[Split, list[str], list[tuple]]:
    """The split without the blocks a dropout reaches (``signals.dropouts``: a response that reads one
    value while the excitation moves; ``Measurement.lost``: a run that held no number), the note that says
    so, and the samples it spoils (their residual is no blow's). A dropout reaches the blocks within the
    band-pass's edge of it, and those whose simulation starts from a warm-up that can read it (``_warm``'s
    longest: three periods of the band's low edge). Left in, the baseline fits the step it makes and every
    cause is fitted to it: independent seeds 8 and 15 ("none") with a response read as 0 for 2 s got a
    contact (gain 0.061) and a joint (0.054). The dropouts stay, and the note says to cut the record, where
    they reach more than a third of the blocks or the last training or held-out block (a ``--train``
    slice is one block)."""
    fs = prep.fs_hz
    after = max(prep.edge, int(3.0 * fs / float(prep.band[0])))
    spans = [(int((g.start_s - prep.start_s) * fs) - prep.edge,
              int(np.ceil((g.stop_s - prep.start_s) * fs)) + prep.edge + after) for g in gaps]
    inside = [(g, sp) for g, sp in zip(gaps, spans) if sp[1] > 0 and sp[0] < prep.n]
    hit = blocks_reached(split, [sp for _, sp in inside])
    if not hit:
        return split, [], []
    said = _said([g for g, _ in inside])
    kept = split.without(hit)
    if len(hit) > len(split.blocks) // 3 or not kept.train or not kept.test:
        why = ("too many to leave out" if len(hit) > len(split.blocks) // 3
               else "and with them the last training or held-out data")
        return split, [f"{said}: {WHAT_DROPS} that reaches {len(hit)} of {len(split.blocks)} blocks, {why}: cut "
                       "the record around it (--train, --test)"], []
    return kept, [f"left out blocks {hit}: {said}: {WHAT_DROPS}"], [sp for _, sp in inside]


def _input_clipped(excitation: Channel, share: float = 0.002, run: int = 3) -> list[str]:
    """A note where the excitation's samples stay at its extreme value for ``run`` samples or more in a row,
    ``share`` of them or more in all (as recorded): its sensor or amplifier reached full scale, so the
    measured input is not all of what drove the structure. Nothing models that: the baseline's error carries
    it, and every gain is measured against that baseline (a one-mode oscillator's random force clipped at 2
    standard deviations, 4.6 % of the samples: held out at 0.077 against 0.034, nothing found, and nothing
    had said why). Runs, not samples: a synthesised sine at a rate that divides the sampling rate repeats
    its peak value exactly once a period, and that is no clipping."""
    a = np.abs(np.asarray(excitation.values, float))
    top = float(np.max(a)) if a.size else 0.0
    if not top > 0:
        return []
    edges = np.diff(np.concatenate([[0], (a >= top * (1 - 1e-6)).astype(np.int8), [0]]))
    lengths = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    flat = float(lengths[lengths >= run].sum()) / a.size
    if flat < share:
        return []
    return [f"the excitation {excitation.name} is clipped at {top:.4g} ({100 * flat:.1f} % of its samples flat "
            "at that full scale): the measured input is not all of what drove the structure, and the baseline's "
            "error holds the difference"]


MIN_SLICE = 100  # samples a given training or test slice keeps at least once decimated (as ``parse_split``)


def _within_budget(m: Measurement, fit_data: Measurement | None, train: slice | None, test: slice | None,
                   max_samples: int):
    """The record (and ``fit_data``, decimated as the record when it has its rate) as
    ``signals.within_budget`` leaves them, the given training and test samples mapped onto what is
    analysed, and the notes that say what was done."""
    keep, kept = None, "the training and test samples"
    if train is not None or test is not None:  # the defaults of ``split.given``
        tr = train or slice(0, int(0.6 * m.n))
        te = test or slice(tr.stop, m.n)
        keep = (min(tr.start, te.start), max(tr.stop, te.stop))
        if test is None:
            kept = "--train and the held-out samples after it (by default to the record's end; give --test)"
        elif train is None:
            kept = "--test and the training samples (by default the record's first 60 %; give --train)"
    ex = within_budget(m, max_samples, keep, kept=kept)
    notes = list(ex.notes)
    if keep is not None and ex.measurement is not m:
        n = ex.measurement.n
        train, test = (slice(max(0, ex.index(s.start)), min(n, ex.index(s.stop))) for s in (tr, te))
        for name, s, asked in (("--train", train, tr), ("--test", test, te)):
            if s.stop - s.start < MIN_SLICE:
                raise ValueError(f"{name} {asked.start}:{asked.stop} keeps {s.stop - s.start} samples once decimated "
                                 f"{ex.step} x to fit the memory budget; give at least {MIN_SLICE * ex.step} samples")
    if fit_data is not None:
        same_rate = fit_data.fs_hz == m.fs_hz
        fx = within_budget(fit_data, max_samples, step=ex.step if same_rate and ex.step > 1 else None)
        fit_data = fx.measurement
        notes += [f"fit data: {n}" for n in fx.notes]
    return ex.measurement, fit_data, train, test, notes


def noise_floor(d: Discovery, m: Measurement, reference: Measurement, settings: Settings = Settings()) -> float:
    """The held-out NRMSE that the responses' difference from ``reference`` alone gives, on the blocks, the
    band and the scale ``d`` (``discover`` on ``m``) was scored with: what no model of ``reference`` can go
    below, so that 1 - floor / ``d.baseline_test_nrmse`` bounds the gain any cause could show.

    ``reference`` is ``m`` as its instruments saw it before their noise, range and quantisation (a generator
    knows it; a lab does not). Only the responses' noise is counted, not what the excitation's noise
    drives through a model, and a clipped response's clipping counts as noise: a floor, not the error of
    the best model. The difference is taken as recorded, then decimated and cut as ``discover`` analysed
    ``m`` (given no ``train`` or ``test`` slice) and band-passed alike (every step linear); signs do not
    change an RMS."""
    if reference.n != m.n or reference.fs_hz != m.fs_hz or [c.kind for c in reference.responses] != [
            c.kind for c in m.responses]:
        raise ValueError("the reference must be the record's responses, sample for sample, in the same kinds")
    diff = Measurement(m.fs_hz, m.excitation, tuple(
        Channel(c.name, c.kind, np.asarray(c.values, float) - np.asarray(r.values, float))
        for c, r in zip(m.responses, reference.responses) if c.name in d.prep.names),  # those analysed (not dead)
        m.start_s)
    ex = within_budget(m, settings.max_samples)
    if ex.step > 1:  # decimated alike (by the step alone: the span is cut below, as the record's was)
        diff = within_budget(diff, np.iinfo(np.int64).max, step=ex.step).measurement
    a = ex.start // ex.step
    p = d.prep
    rows = d.split.rows("test")
    noise = np.column_stack([convert(np.asarray(c.values, float)[a:a + p.n], p.fs_hz, p.band, ORDER[c.kind],
                                     ORDER[c.kind]) for c in diff.responses])
    scale = np.maximum(p.measured[rows].std(axis=0), 1e-300)
    return float(np.mean(np.sqrt(np.mean(noise[rows] ** 2, axis=0)) / scale))


def _discover(m: Measurement, rig: RigParams | None, fit_data: Measurement | None, train: slice | None,
              test: slice | None, settings: Settings, say: Callable[[str], None],
              budget_notes: list[str], clip_ranges: list[float | None],
              input_notes: list[str] | None = None, gaps: tuple[Dropout, ...] | list[Dropout] = (),
              fit_gaps: tuple[Dropout, ...] | list[Dropout] = (), harmonics: float = HARMONICS) -> Discovery:
    notes: list[str] = list(budget_notes) + list(input_notes or [])
    for line in notes:
        say(line)
    say(f"{m.n} samples at {m.fs_hz:g} Hz, {len(m.responses)} responses; "
        + ("the rig model is the baseline" if rig is not None else "fitting a modal baseline, its order on held-out"
           " blocks"))
    if rig is not None:
        baseline: Baseline = RigBaseline(rig)
        band = modal_band(baseline.model.frequencies_hz, m.fs_hz, m.n)
        prep = prepare(m, band)
    else:
        band, poles0 = _fit_modal(m, fit_data, train, test, harmonics)
        prep = prepare(m, band)
        for line in below_band(m, prep.band):
            notes.append(line)
            say(line)
        say(f"first fit: {poles0.size} lightly damped mode{'' if poles0.size == 1 else 's'}, band {band[0]:.3g}-"
            f"{band[1]:.3g} Hz; fitting there again")
    f_min = float(prep.band[0]) / 0.4
    split = _split(prep, train, test)
    # a dropout's blocks out of the baseline's fit, the scoring and the causes' training. The first fit, which
    # chose the band and the order, saw the record whole: a dropout left out there too had the order chosen
    # on other held-back blocks, and lost independent seed 8's second mode (held out at 0.25, not 0.04)
    split, said, spoilt = _without_dropouts(split, prep, gaps)
    fit_segments = fit_split = None
    if rig is None and fit_data is not None:
        prep_fit = prepare(fit_data, band)
        fit_split, fit_said, _ = _without_dropouts(_split(prep_fit), prep_fit, fit_gaps)
        said += [f"fit data: {line}" for line in fit_said]
        fit_segments = ((slice(prep_fit.edge, prep_fit.n - prep_fit.edge),) if not fit_split.excluded else
                        fit_split.kept)
    for line in said:
        notes.append(line)
        say(line)
    if rig is None:
        if fit_data is not None:
            baseline = ModalBaseline.fit(prep_fit, rows_of(fit_segments), poles0=poles0)
        else:
            baseline = _fit_in_band(prep, split, poles0)
    warm = _warm(baseline, prep)
    bound = simulation_bound(prep)

    # unmodelled transients: isolated bursts of the baseline's error. Each block is predicted from the
    # state read off the data before it, so a blow's burst ends with the block it strikes in; predicted
    # past its end, so the band-pass's edge makes no burst at the block's end (independent seed 54)
    resid_all = np.full((prep.n, len(prep.names)), np.nan)
    for seg in split.blocks:
        resid_all[seg] = prep.measured[seg] - predict(baseline, baseline.model, prep, seg, warm, past=prep.edge)
    for a, b in spoilt:  # a dropout's step is no blow, nor the start of a block simulated from it
        resid_all[max(a, 0):max(b, 0)] = 0.0
    period = max(4, int(prep.fs_hz / f_min))
    rows = rows_of(split.blocks)
    longest = 2 * max(b.stop - b.start for b in split.blocks) + warm
    # (not in the first block's warm-up: its start is read off too little data to tell a blow from it)
    starts = np.cumsum([0] + [b.stop - b.start for b in split.blocks[:-1]])
    spans = [(int(rows[0] + a), int(rows[0] + b))
             for a, b in transients(np.nan_to_num(resid_all[rows]), period, longest, excitation=prep.u[rows],
                                    starts=starts)
             if a >= warm]
    onsets = [a for a, _ in spans]
    if spans:
        hit = blocks_reached(split, spans)
        # a few isolated bursts are blows (at most one per five blocks, two at least), and at least two
        # thirds of the blocks stay; bursts all over the record are the structure's own behaviour
        if len(spans) <= max(2, len(split.blocks) // 5) and len(hit) <= len(split.blocks) // 3:
            fitted_on = split.rows("train")
            split = split.without(hit)
            prep = replace(prep, blows=tuple(onsets))
            notes.append(f"left out blocks {hit}: transients the measured input cannot produce at "
                         + ", ".join(f"{prep.start_s + t / prep.fs_hz:.2f} s" for t in onsets))
            if rig is None and fit_data is None:
                # the baseline had fitted the blows' ringing as if the input had made it: it is fitted
                # again on the same blocks with a free response of its own from each blow on (a blow is a
                # modal test of its own: leaving its blocks out lost modes, independent seed 12)
                baseline = ModalBaseline.fit(prep, fitted_on, poles0=baseline.model.poles)
                warm = _warm(baseline, prep)
                notes.append("the modal baseline fitted again with a free response from each blow on")
        else:
            onsets = []
    # either baseline: the data alone say it, on the blocks that stay (a blow nobody measured rings high too)
    above = above_band(m, prep.band, keep=split.kept if split.excluded and split.kept else None)
    wide = min(0.45 * m.fs_hz, prep.band[1] * WIDE_HARMONICS / harmonics)  # (``modal_band``'s top)
    if above and rig is None and fit_data is None and harmonics < WIDE_HARMONICS and wide > 1.5 * prep.band[1]:
        # motion the input does not drive above the band: a search in the band misses what makes it
        # (``WIDE_HARMONICS``); analysed again, the band reaching that far
        again = (f"analysed again in a band to {WIDE_HARMONICS:g} x the highest mode ({wide:.3g} Hz), not "
                 f"{harmonics:g} x ({prep.band[1]:.3g} Hz), for the motion above it")
        return _discover(m, rig, fit_data, train, test, settings, say, budget_notes, clip_ranges,
                         list(input_notes or []) + above + [again], gaps, fit_gaps, WIDE_HARMONICS)
    for line in above:
        notes.append(line)
        say(line)
    test_rows = split.rows("test")
    scale = np.maximum(prep.measured[test_rows].std(axis=0), 1e-300)
    piece = max(16, int(PIECE_PERIODS * prep.fs_hz / f_min))
    e0, n0 = block_errors(baseline, baseline.model, prep, split.test, warm, scale, (), bound, piece)
    sc = Scoring(scale, e0, n0, warm, bound, piece, settings.gain_floor, settings.alpha,
                 moving_pieces(prep, split.test, scale, piece))
    kind = "rig model" if rig is not None else "modal model"
    k = len(baseline.model.frequencies_hz)
    say(f"baseline: {kind} with {k} mode{'' if k == 1 else 's'}, band {prep.band[0]:.3g}-"
        f"{prep.band[1]:.3g} Hz, held-out NRMSE {n0:.4g} over {len(split.test)} blocks")

    residual = baseline_residual(baseline, prep, split, warm)
    train_rows = split.rows("train")
    train_rows = train_rows[np.all(np.isfinite(residual[train_rows]), axis=1)]
    resid_rms = {n: float(np.sqrt(np.mean(residual[train_rows, i] ** 2))) for i, n in enumerate(prep.names)}
    locations = baseline.locations(prep)
    char = characterise(baseline, prep, train_rows, residual, locations, scale)
    # (with --fit-data the baseline's driving point is the fit record's, which the alike ones are not)
    if (fit_data is None and prep.driving_alike and isinstance(baseline, ModalBaseline)
            and baseline.driving_point is not None):
        baseline, char = _reciprocity(baseline, prep, train_rows, residual, locations, scale, char, notes)
    ranked = sorted(locations, key=lambda loc: -char[loc.name]["explained"])[:settings.max_locations]
    say(f"characterised {len(locations)} locations; regressing every cause at the {len(ranked)} that explain most")

    joint = fit_data is None and hasattr(baseline, "fit_jointly")
    cands, compensated = _regressed(baseline, prep, train_rows, residual, ranked, scale, joint, settings, notes)
    raw = np.column_stack([prep.signs[i] * np.asarray(ch.values, float) for i, ch in enumerate(m.responses)])
    cands += clipping_candidates(prep, clip_ranges)
    if "sensor_gain" in baseline.causes:
        cands += gain_candidates(baseline, prep, split, warm)

    # refine each cause's best location (by the regression), then score everything on held-out blocks
    by_loc = {loc.name: loc for loc in locations}
    fit_record = None
    if fit_data is not None:
        fit_record = FitLevel(prep_fit, fit_segments, fit_split, _warm(baseline, prep_fit))
    fitted_here = rig is None and fit_data is None
    refined = _refined(cands, baseline, by_loc, prep, split, warm, scale, bound, settings, joint, fit_record,
                       fitted_here, say, notes)
    other = None
    if fitted_here and isinstance(baseline, ModalBaseline):
        other = _fewer_modes(baseline, prep, split) or _one_more_mode(baseline, prep, split)
    if other is not None:
        # the same search on the linear part of the fewest modes the order search allows up to the responses'
        # count (``_fewer_modes``), or of one mode more where the baseline has fewer than the responses
        # (``_one_more_mode``); its candidates carry that linear part as their own and are scored against
        # the baseline
        k0, k1 = (int(np.count_nonzero(b.drivable)) for b in (baseline, other))
        say(f"the baseline has {k0} modes for {len(prep.names)} responses: searching again on {k1}")
        res2 = baseline_residual(other, prep, split, warm)
        rows2 = split.rows("train")
        rows2 = rows2[np.all(np.isfinite(res2[rows2]), axis=1)]
        more, _ = _regressed(other, prep, rows2, res2, ranked, scale, joint, settings, notes, compensate=False)
        more += _refined(more, other, by_loc, prep, split, warm, scale, bound, settings, joint, None, fitted_here,
                         say, notes, what=f"on {k1} modes")
        refined += [replace(c, baseline=c.baseline or other) for c in more if c.elements]
    say(f"scoring {len(cands) + len(refined)} candidates on the held-out blocks")
    scored = [score(c, baseline, prep, split, sc) for c in cands + refined]
    if other is not None:
        scored = [_fewer_on_their_own(c, baseline) for c in scored]
    scored.sort(key=_by_gain)
    for c in scored:
        if c.note.startswith("failed"):
            notes.append(f"{c.label}: {c.note}")

    # fit data: a cause must hold at the other level too (not spoil the baseline's fit there)
    if fit_data is not None:
        say("checking the significant ones at the fit record's level")
        scored = _hold_at_fit_level(scored, baseline, fit_record, f_min, settings)

    sel = _select(findable(scored, fitted_here, char), baseline, prep, split, sc, settings, char)
    # (not behind a baseline worse than predicting zero: its linear part does not describe the record, and
    # there is no equivalent linearisation in it to take out; on stop 57's benchmark the three such records
    # with nothing found, 3, 25 and 82, got nothing from the second step either)
    if not sel.findings and compensated and n0 <= 1.0:
        # nothing found: the causes with their equivalent linearisation taken out of the fitted linear part
        # are the second step (``search.regressions``). Scored with the others, they made weak causes
        # findable but tied with true ones where the plain search named them (independent seed 20: a joint
        # named right became "cubic or joint"), so they come only after it found nothing. What it cannot
        # separate stays a note: on stop 57's benchmark three of its five ambiguous answers named another
        # place first (independent seeds 0, 29, 87; 16 and 70 named the right cause first)
        say(f"nothing found; scoring {len(compensated)} causes regressed with their equivalent linear part "
            "taken out")
        comp_scored = [score(c, baseline, prep, split, sc) for c in compensated]
        scored = sorted(scored + comp_scored, key=_by_gain)
        second = _select(findable(scored, fitted_here, char), baseline, prep, split, sc, settings, char)
        if second.findings:
            # what leads is refined by simulation, as every leading cause of the first step is (its spring
            # and damper scaled with it), and chosen again among all
            again = []
            for c in [second.findings[0]] + second.ambiguous[0]:
                if not compensation(c) or c.refined:
                    continue
                say(f"refining by simulation: {c.label} with its spring and damper")
                try:
                    again.append(score(refine(c, baseline, by_loc[c.location], prep, split, warm, scale, bound,
                                              settings, joint=False), baseline, prep, split, sc))
                except NUMERIC_FAILURES as exc:
                    notes.append(f"{c.label} with its spring and damper: refinement failed ({exc})")
            if again:
                comp_scored += again
                scored = sorted(scored + again, key=_by_gain)
                second = _select(findable(scored, fitted_here, char), baseline, prep, split, sc, settings,
                                 char)
        if second.findings and second.ambiguous[0]:
            names = " or ".join(options(second.findings[0], second.ambiguous[0]))
            notes.append(f"with the equivalent linear part taken out, {names} would gain "
                         f"{second.findings[0].gain:.2g} on held-out blocks; the data cannot separate them")
        else:
            sel = second
        if not second.findings:
            notes += _linear_corrections(comp_scored, settings)
    notes += _set_aside(scored, sel.findings) + _engaged_aside(scored, sel.findings, char, settings)
    ext_model, ext_out, ext_err, ext_blocks = baseline.model, (), n0, e0
    if sel.findings:
        own = sel.findings[0].baseline or baseline
        elements = tuple(el for f in sel.findings for el in f.elements)
        ext_out = tuple(o for f in sel.findings for o in f.output)
        ext_model = own.model.with_elements(elements)
        ext_blocks, ext_err = block_errors(own, ext_model, prep, split.test, warm, scale, ext_out, bound, piece)
    if "sensor_offset" in baseline.causes:
        offsets = offset_findings(prep, raw, split, piece, settings)
        sel = Selection(sel.findings + offsets, sel.ambiguous + [[] for _ in offsets],
                        [] if offsets and not sel.findings else sel.reasons)
    if sel.findings and other is not None and sel.findings[0].baseline is not None:
        mine = sel.findings[0].baseline.model.poles
        k0, k1 = (int(np.count_nonzero(drivable(p, prep))) for p in (baseline.model.poles, mine))
        if k1 < k0:
            notes.append(f"{sel.findings[0].label} comes with a linear part of {k1} mode{'' if k1 == 1 else 's'}, where "
                         f"the linear fit to this record has {k0}: the fit's extra modes were its way of following "
                         "the nonlinear response, and the gain is measured against that fit")
        elif k1 > k0:
            notes.append(f"{sel.findings[0].label} comes with a linear part of {k1} modes, where the linear fit to "
                         f"this record has {k0}: the order search turned the other mode away (a resonance the "
                         "nonlinearity smears), and the gain is measured against that fit")
    notes = sel.reasons + notes + sum_notes(sel.findings, by_loc, prep.names)
    if n0 > 1.0:  # NRMSE 1 is predicting zero
        notes.append(f"the baseline predicts the held-out blocks worse than predicting zero (NRMSE {n0:.3g}): its "
                     "linear part does not describe this record, and every gain here is measured against it")
    return Discovery(baseline, n0, e0, ext_model, ext_out, ext_err, ext_blocks, sel.findings, sel.ambiguous, scored,
                     split, prep, warm, [prep.start_s + t / prep.fs_hz for t in onsets], resid_rms, char, notes)


def _settle_by_backbone(first: Candidate, alike: list[Candidate], scored: list[Candidate], prep: Prepared,
                        char: dict, settings: Settings) -> tuple[Candidate, list[Candidate], str]:
    """A hammer-hit record rings down through every amplitude, and its free decays' backbone (``backbone``)
    shows the stiffness law directly: a cubic's glide grows with amplitude^2, a quadratic stiffness's with
    amplitude, a stopper's starts at its gap. Where the first finding and the candidates at its response that
    beat the baseline (``search.beats_baseline``), over their own refitted linear part or not (a linear part
    refitted to a decay takes up the mean of its glide; independent seed 749's cubic: 0.067 at p = 1e-4 over
    the baseline, p = 0.16 over its own part, where a quadratic stiffness was named at 0.049), include
    stiffness laws of two causes or more, each candidate's shape (its describing
    stiffness at the backbone's amplitudes, ``catalogue.describing_stiffness``, its scale free) is fitted
    to the measured backbone; a cause whose shape fits significantly worse than the best
    (``Backbone.set_aside``) is set aside, the first finding too (then the best-gaining candidate of a
    cause that fits takes its place).
    The held-out error over a hammer record's few blocks weighs the linear part's and the damping's errors
    with the law's; the backbone weighs the law alone (a stopper's decay glides down to its gap and no
    further, a cubic's on as amplitude^2: ``test_discovery_parts``). Returns the first finding, its
    look-alikes left and the reason ("" if unsettled); the backbone goes into the characterisation."""
    if not prep.transient or first.location not in prep.names:
        return first, alike, ""
    probe = np.ones(1)
    stiff = lambda c: describing_stiffness(c.cause, c.parameters, probe) is not None  # noqa: E731
    here, seen = [], set()
    for c in [first] + alike + [c for c in scored if beats_baseline(c, settings)]:
        if c.location == first.location and id(c) not in seen and stiff(c):
            here.append(c)
            seen.add(id(c))
    if len({c.cause for c in here}) < 2 or not stiff(first):
        return first, alike, ""
    k = prep.names.index(first.location)
    y = prep.measured[:, k]
    spectrum = np.abs(np.fft.rfft(y * np.hanning(y.size)))
    f = np.fft.rfftfreq(y.size, 1.0 / prep.fs_hz)
    inband = (f >= prep.band[0]) & (f <= prep.band[1])
    if not inband.any():
        return first, alike, ""
    bb = free_decay(first.location, y, prep.u, prep.fs_hz, float(f[inband][np.argmax(spectrum[inband])]))
    if bb is None:
        return first, alike, ""
    char.setdefault(first.location, {})["backbone"] = bb.as_json()
    displacement = bb.amplitude / (2 * np.pi * bb.frequency_hz) ** ORDER[prep.kinds[k]]
    errs: dict[str, float] = {}
    for c in here:
        e = bb.shape_error(describing_stiffness(c.cause, c.parameters, displacement))
        errs[c.cause] = min(errs.get(c.cause, np.inf), e)
    out = bb.set_aside(errs)
    if not out:
        return first, alike, ""
    # a look-alike at another response was not judged by this backbone: it stays
    kept = [c for c in [first] + alike if not (c.location == first.location and c.cause in out)]
    if first.cause in out:
        fitting = [c for c in here if c.cause not in out]
        first = max(fitting, key=lambda c: c.gain)
        kept = [first] + [c for c in kept if c is not first]
    shapes = ", ".join(f"{cause} {e:.2g} Hz" for cause, e in sorted(errs.items(), key=lambda t: t[1]))
    reason = (f"the free decays' backbone at {first.location} ({bb.mode_hz:.1f} Hz) against each stiffness law's "
              f"shape (RMS off its best line: {shapes}): {', '.join(sorted(out))} set aside")
    return first, [c for c in kept if c is not first], reason


SOFTENING_SHARE = 0.75  # a softening cubic's joint look-alike gains at least this share of the cubic's gain


def _softening_look_alike(first: Candidate, alike: list[Candidate], scored: list[Candidate],
                          settings: Settings) -> list[Candidate]:
    """The look-alike a first finding that softens gets even where it beat it: the best significant
    candidate, between the same sensors, of the mechanism its law then describes
    (``Cause.softening_mechanism``: a cubic with k3 < 0 and a joint that slips), where that candidate gains
    at least ``SOFTENING_SHARE`` of what the finding gains. The paired test between the two says how well
    each law was fitted, and a joint's has more to fit (its slip, its onset); on the independent generator
    the softening cubics named first were hidden joints (seeds 29, 45, 54, 74, 99) or a drag (50), stop 54's
    benchmark.

    The share is measured (stop 55): on 22 force-driven Duffing oscillators whose cubic softens (the
    generator's ``duffing_softening`` family, seeds 0-29), a significant joint fitted every one of the 16
    whose cubic was named first and alone, gaining 0.10-0.65 of the cubic's gain; without the share all
    16 were "ambiguous". Seed 45's hidden joint gained 0.84 of the cubic named there (0.119 against
    0.141) and stays ambiguous. Seed 99's gained 0.50 (0.344 against 0.687): no share tells it from the
    Duffings, and it is named a cubic, wrongly, as before the rule."""
    mechanism = CAUSES[first.cause].softening_mechanism
    if not softens(first) or any(a.cause == mechanism for a in alike):
        return []
    there = [c for c in scored if c.cause == mechanism and same_sensors(c.location, first.location)
             and significant(c, settings) and c.gain >= SOFTENING_SHARE * first.gain]
    return [max(there, key=lambda c: c.gain)] if there else []


ENGAGED_GAP = 0.2  # a two-sided stopper's gap under this share of the largest displacement there: a spring


def engaged_throughout(c: Candidate, char: dict) -> bool:
    """Is ``c`` a two-sided stopper whose gap is under ``ENGAGED_GAP`` of the largest displacement at its
    location over the training blocks (the characterisation's range)? Such a stopper holds the beam through
    nearly all of its motion: its force, k (x - g sign x) beyond the gap, is a linear spring k less a step
    of k g, and the spring is what its own linear part, refitted with it, already holds. On a sinusoid that
    reaches the largest displacement, the share of its force (RMS) that no spring takes is 13 % at this
    threshold, 6 % at a gap of 0.1 and 27 % at 0.41 (least squares on the displacement; the slope is the
    describing function's, ``catalogue.describing_stiffness``): little of a stopper is left to name.

    Measured on the independent generator's seeds 100-199 at stop 83 (`8a5bcb3`): the two false contacts
    named first had gaps of 0.04 (seed 116, nothing hidden: engaged in 94 % of the samples, 0.2 % of the
    mode's stiffness) and 0.10 (seed 103, a true contact at tip 2 named between the tips) of that range; the
    thirteen contacts named right, 0.41 to 0.98. A one-sided stopper at a small gap stays a candidate: it is
    a bilinear spring, as nonlinear as a stopper gets."""
    if c.cause != "contact" or c.parameters.get("side") != "both":
        return False
    largest = _largest_displacement(char, c.location)
    return largest > 0 and c.parameters.get("gap", np.inf) < ENGAGED_GAP * largest


def _largest_displacement(char: dict, location: str) -> float:
    """The largest |displacement| at a location over the training blocks (the characterisation's range; 0
    where it has none)."""
    span = char.get(location, {}).get("displacement")
    return max(abs(span[0]), abs(span[-1])) if span else 0.0


def findable(scored: list[Candidate], fitted_here: bool, char: dict | None = None) -> list[Candidate]:
    """The candidates a finding may be: all of them, except a linear mismatch against a modal model
    fitted to this very record (``fitted_here``), and a two-sided stopper engaged through nearly all of
    the motion (``engaged_throughout``, with the characterisation ``char``). A modal model was fitted to
    these data by least squares; a linear change that predicts them better is the fit's own imperfection,
    not a cause (independent seed 32's twin, a linear record: a linear mismatch at tip 2, gain 0.05). The
    mismatch is still scored (as regressed, not refined) and listed; against a rig model from a config, or
    a baseline fitted on another record (``--fit-data``), the linear part can be wrong, and it can be a
    finding."""
    if char:
        scored = [c for c in scored if not engaged_throughout(c, char)]
    if not fitted_here:
        return scored
    return [c for c in scored if c.cause != "linear_mismatch"]


def _regressed(baseline: Baseline, prep: Prepared, rows: np.ndarray, residual: np.ndarray, ranked: list,
               scale: np.ndarray, joint: bool, settings: Settings, notes: list[str],
               compensate: bool = True) -> tuple[list[Candidate], list[Candidate]]:
    """Every cause regressed at every ranked location on the baseline's training residual, and the best
    regressions fitted again together with the baseline's linear part (``joint``: their shapes searched again;
    the rest keep the baseline's); with ``compensate`` also each cause regressed with a spring and a damper at
    its coordinate (the second list).

    A baseline fitted to this record absorbed part of any nonlinearity (its equivalent stiffness and damping
    at the record's amplitudes): the joint fit and the spring and damper take that part out again. A baseline
    fitted to a separate (low-level) record has seen no nonlinearity: its linear part stays."""
    cands: list[Candidate] = []
    compensated: list[Candidate] = []
    for loc in ranked:
        try:
            lin = spring_damper_responses(baseline, prep, rows, loc, scale) if joint and compensate else None
        except NUMERIC_FAILURES as exc:
            notes.append(f"the spring and damper at {loc.name}: regression failed ({exc})")
            lin = None
        for cause in baseline.causes:
            if cause in ("clipping", "sensor_gain", "sensor_offset"):
                continue
            try:
                c, cc = regressions(baseline, prep, rows, residual, loc, cause, scale,
                                    compensate=lin if cause != "linear_mismatch" else None)
            except NUMERIC_FAILURES as exc:
                notes.append(f"{cause} at {loc.name}: regression failed ({exc})")
                continue
            cands += [c] if c is not None else []
            compensated += [cc] if cc is not None else []
    if joint:
        order = sorted(range(len(cands)), key=lambda i: -cands[i].fit_r2)[:settings.max_joint]
        for i in order:
            loc = next(loc for loc in ranked if loc.name == cands[i].location)
            try:
                again = regress(baseline, prep, rows, residual, loc, cands[i].cause, scale, joint_shapes=3)
            except NUMERIC_FAILURES as exc:
                notes.append(f"{cands[i].label}: joint fit failed ({exc})")
                continue
            if again is not None:
                cands.append(again)
    return cands, compensated


def _refined(cands: list[Candidate], baseline: Baseline, by_loc: dict, prep: Prepared, split: Split, warm: int,
             scale: np.ndarray, bound: float, settings: Settings, joint: bool, fit_record: FitLevel | None,
             fitted_here: bool, say: Callable[[str], None], notes: list[str], what: str = "") -> list[Candidate]:
    """The leading candidates (``_leaders``) refined by simulation on the baseline."""
    leaders = _leaders(cands, baseline, by_loc, prep, split, warm, scale, bound, settings,
                       next_place=fit_record is not None)
    if fitted_here:
        # a linear mismatch is no finding against a model fitted to this record (``findable``): it keeps its
        # place among the leaders (so the others refined stay the same) but is not refined. Its refinement
        # was the dearest of all: a spring stiff enough that the integrator takes its cap of 64 sub-steps a
        # sample, 98 of the 163 s of independent seed 2's run, for a candidate that cannot be chosen
        leaders = [c for c in leaders if c.cause != "linear_mismatch"]
    out = []
    for k, c in enumerate(leaders, start=1):
        say(f"refining {k} of {len(leaders)} by simulation{' ' + what if what else ''}: {c.label}")
        try:
            out.append(refine(c, baseline, by_loc[c.location], prep, split, warm, scale, bound, settings,
                              joint=joint, fit=fit_record))
        except NUMERIC_FAILURES as exc:
            notes.append(f"{c.label}: refinement failed ({exc})")
    return out


def _fewer_modes(baseline: ModalBaseline, prep: Prepared, split: Split) -> ModalBaseline | None:
    """The baseline of the order the order search chooses up to the responses' count, where the fitted one
    has more modes a force may drive than there are responses and this one fewer (and at least one); else None.

    A linear fit to a nonlinear record buys its error down with modes the structure does not have: poles
    beside the true ones that spread a hardening or a stopper's resonance over the amplitudes the record
    passes through (independent seed 617, two beams and a stopper: five poles between 9.1 and 11.4 Hz,
    where the beams have two modes; seed 697, a cubic: 8.31, 9.04 and 9.08 Hz). Every cause regressed against that
    baseline finds its residual already taken, and nothing is found (617) or the wrong cause (697).
    Searched again on the fewer modes, a cause with its own linear part must still beat the fitted baseline
    on the held-out blocks to be a finding."""
    k = len(prep.names)
    if np.count_nonzero(drivable(baseline.model.poles, prep)) <= k:
        return None
    rows, at = _held_back(split.train)
    try:
        poles = ModalBaseline.fit(prep, rows, max_modes=k, check=at).model.poles
        fewer = _without_devices(ModalBaseline.fit(prep, split.rows("train"), poles0=poles), prep, split)
    except NUMERIC_FAILURES:
        return None
    n = np.count_nonzero(drivable(fewer.model.poles, prep))
    if not 0 < n < np.count_nonzero(drivable(baseline.model.poles, prep)):
        return None
    if baseline.driving_point is not None:
        fewer = fewer.through(baseline.driving_point, baseline.driving_sign)
    return fewer


def _one_more_mode(baseline: ModalBaseline, prep: Prepared, split: Split) -> ModalBaseline | None:
    """The baseline fitted again on the training blocks with one mode a force may drive more, where the fitted
    one has fewer such modes than there are responses (and at least one); else None. Its starting poles are
    the order search's two starts (vector fitting, the FRF's peaks) on the training blocks' FRF
    (``modal.band_lines``), the one whose fit ends with more drivable modes and the smaller fit error kept.

    The order search chooses on what the input alone makes on held-back blocks, from rest: where a beam
    strikes its stopper through the record, no linear model predicts its response there (independent seed
    915, a two-sided stopper at tip 1: one mode, 1.17 times predicting zero at tip 1; two, 1.45), and the
    order stops at the other beam's mode. Two modes, 12.18 Hz (the struck beam's) and 13.47 Hz, fit the
    training blocks at 0.064 against one mode's 0.30; searched on them, the stopper is found at tip 1 (gap
    0.5 % off), where on one mode a quadratic stiffness there had been named. The gain is still measured
    against the fitted baseline, and a cause must beat its own linear part (``significant``).

    On seeds 900-999 (stop 89) twelve records took the search, none of the others moved: 915 and 973 right,
    985 right with its gap 8.2 % off (15 % by stop 88's next-place step, which this search replaced), two
    wrong answers changed for others; each searched record takes about twice as long. No record with nothing
    hidden among seeds 0-299 has fewer fitted modes than responses."""
    k = len(prep.names)
    have = int(np.count_nonzero(baseline.drivable))
    if not 0 < have < k:
        return None
    rows = split.rows("train")
    try:
        f, H = band_lines(prep, rows)
    except NUMERIC_FAILURES:
        return None
    if f.size < 4 * (have + 1):  # as few lines per mode as the order search allows
        return None
    best = None
    for start in (vector_fit_poles, peak_poles):
        try:
            poles = start(f, H, have + 1)
            if poles is None:
                continue
            fitted = _without_devices(ModalBaseline.fit(prep, rows, poles0=poles), prep, split)
        except NUMERIC_FAILURES:
            continue
        if np.count_nonzero(fitted.drivable) > have and (best is None or fitted.fit_nrmse < best.fit_nrmse):
            best = fitted
    if best is not None and baseline.driving_point is not None:
        best = best.through(baseline.driving_point, baseline.driving_sign)
    return best


FEWER_ALONE = "its linear part alone, with fewer modes than the baseline, predicts better than the baseline"


def _fewer_on_their_own(c: Candidate, baseline: Baseline) -> Candidate:
    """A candidate of the search on fewer modes (``_fewer_modes``: its own linear part has fewer poles than the
    baseline) is no finding where that linear part alone predicts the held-out blocks better than the baseline
    (``own_gain < gain``, the rule a compensated candidate meets in ``significant``): the claim is that the
    baseline's extra modes stand for the cause, so without the cause those modes must be missed. Independent
    seed 42, a chain whose five fitted modes are all its own: a contact on four of them gained 0.14 on the
    baseline and 0.01 on its own linear part, and made the true cubic "ambiguous"."""
    if c.baseline is None or c.baseline.model.poles.size >= baseline.model.poles.size:
        return c
    if np.isfinite(c.gain) and c.gain > 0 and not c.own_gain >= c.gain:
        return replace(c, p_value=1.0, note=f"{FEWER_ALONE} ({c.own_gain:.2g} against {c.gain:.2g})")
    return c


def _leaders(cands: list[Candidate], baseline: Baseline, by_loc: dict, prep: Prepared, split: Split, warm: int,
             scale: np.ndarray, bound: float, settings: Settings, next_place: bool = False) -> list[Candidate]:
    """The candidates worth refining by simulation, one per cause, at most ``settings.max_refined``:
    first the causes whose regression simulates the busiest training blocks at its location clearly
    better than the baseline (the best such version), then the causes whose regression explains a share
    of the residual (the best share), however it simulates as regressed, then the barely better ones.

    A regression's share of the residual alone does not rank them: a version fitted jointly with the
    linear part is scored against another residual than its plain twin, and a hysteretic force explains
    little of a residual it still predicts well (independent seed 11: the joint's regression explains 2 %
    of it and gains 0.35 on held-out blocks). Nor does the simulation alone: a stopper's regression is
    a soft spring at a smaller gap, or a stiff one the simulation cannot follow, which only the
    refinement's scan corrects (independent seed 60: explains 24 %, simulates to the bound).

    With ``next_place`` (a fit record: every refined version must hold at a second level too) the leading
    cause is refined at its next place as well (the best other location by the same ranking), one
    refinement more: the regression tells causes apart better than places (the characterisation's share
    explained is 0.19 at every location of independent seed 72's chain), and on the F-16 the joint at
    Acceleration2 leads while the joint on the pair 2, 3, refined, predicts level 7 better (0.349 against
    0.369) and holds at level 1. Without a fit record the extra place measured worse: on the independent
    generator's seeds 0-99, 64 named right and 88 without a false extra finding against 65 and 89 (seed 86's
    contact at tip 1 became ambiguous with its look-alike at another place; seed 72's chain, "nothing"
    before, named a contact at a wrong pair with a false extra finding). One record cannot tell two places
    of a cause apart as well as two levels can, so the benchmark's path (no fit record) does not. (Stop 88
    refined it there where nothing was found and the leading cause gained through its own linear part alone,
    for seed 985; since stop 89 the search on one mode more, ``_one_more_mode``, finds 985, and that step
    moved no verdict of seeds 900-999 and was removed.)"""
    at: dict[str, tuple[tuple[slice, ...], float]] = {}  # per location: its busiest blocks, the baseline's error there
    by_sim: dict[str, tuple[float, Candidate]] = {}
    by_r2: dict[str, Candidate] = {}
    tried: list[tuple[float, Candidate]] = []
    for c in cands:
        if not c.elements or c.fit_r2 <= 0.0:
            continue
        if c.location not in at:
            segs = busiest(prep, split, by_loc[c.location].weights, settings.refine_blocks)
            try:
                at[c.location] = segs, block_errors(baseline, baseline.model, prep, segs, warm, scale, (), bound)[1]
            except NUMERIC_FAILURES:
                at[c.location] = segs, np.inf
        segs, e_0 = at[c.location]
        e_c = train_error(baseline, c, prep, segs, warm, scale, bound)
        e = e_c / e_0 if 0 < e_0 < np.inf else (0.0 if np.isfinite(e_c) else np.inf)
        tried.append((e, c))
        if c.cause not in by_sim or e < by_sim[c.cause][0]:
            by_sim[c.cause] = (e, c)
        rank = (c.fit_r2, c.baseline is not None)  # a jointly fitted version before its plain twin
        if c.cause not in by_r2 or rank > (by_r2[c.cause].fit_r2, by_r2[c.cause].baseline is not None):
            by_r2[c.cause] = c
    sims = sorted(by_sim.values(), key=lambda ec: ec[0])
    order = [c for e, c in sims if e < CLEARLY_BETTER]
    done = {c.cause for c in order}
    order += sorted((c for k, c in by_r2.items() if k not in done and c.fit_r2 > 0.01), key=lambda c: -c.fit_r2)
    done = {c.cause for c in order}
    order += [c for e, c in sims if e < 1.0 and c.cause not in done]
    order = order[:settings.max_refined]
    if next_place and order:  # the leading cause at its next place too (see the docstring)
        first = order[0]
        there = [(e, c) for e, c in tried if c.cause == first.cause and c.location != first.location]
        nxt = min(((e, c) for e, c in there if e < 1.0), key=lambda ec: ec[0], default=None)
        if nxt is None:
            nxt = max(((c.fit_r2, c) for _, c in there if c.fit_r2 > 0.01), key=lambda rc: rc[0], default=None)
        if nxt is not None:
            order.insert(1, nxt[1])
    return order


def _hold_at_fit_level(cands: list[Candidate], baseline: Baseline, fit: FitLevel, f_min: float,
                       settings: Settings) -> list[Candidate]:
    """With a separate record for the baseline (a low level): a cause must hold there too. A candidate
    the baseline predicts significantly and materially better (by the gain floor) on that record's
    held-out blocks is not significant: an
    amplitude-dependent cause explains the high level without breaking the low one, an
    equivalent-linear change does not."""
    prep_fit, split_f, warm = fit.prep, fit.split, fit.warm
    scale_f = np.maximum(prep_fit.measured[split_f.rows("test")].std(axis=0), 1e-300)
    piece = max(16, int(PIECE_PERIODS * prep_fit.fs_hz / f_min))
    e0f, n0f = block_errors(baseline, baseline.model, prep_fit, split_f.test, warm, scale_f, (), np.inf, piece)
    out = []
    for c in cands:
        if significant(c, settings):
            own = c.baseline or baseline
            ef, nf = block_errors(own, own.model.with_elements(c.elements), prep_fit, split_f.test, warm, scale_f,
                                  c.output, np.inf, piece)
            p = paired_p(ef, e0f)
            # significantly and materially worse (``search.displaces``' reason: over a record's pieces a paired
            # test calls a sliver significant; a contact < 0.5 % worse at p = 0.07 was set aside on a Duffing pair)
            if p < settings.alpha and nf > (1.0 + settings.gain_floor) * n0f:
                c = replace(c, p_value=1.0, note=f"{FIT_BREAK}: it predicts that record's held-out blocks "
                                                 f"{nf / n0f - 1:.0%} worse than the baseline (NRMSE {nf:.3g} "
                                                 f"against {n0f:.3g}, p = {p:.1g})")
        out.append(c)
    return out


FIT_BREAK = "breaks the fit record"


def sum_notes(findings: list[Candidate], by_loc: dict, names: tuple[str, ...] | list[str]) -> list[str]:
    """What a finding on a pair's sum means: two responses whose signs the data could not fix against each
    other (neither is a driving point) are searched as a difference and as a sum (``default_locations``), and
    the sum is their relative motion only if one of them reads the other way round; with the signs as
    recorded it is their common motion. A person reading "at A+B" should know which to check."""
    out = []
    for f in findings:
        loc = by_loc.get(f.location)
        if loc is None or len(loc.responses) != 2 or np.any(loc.weights[list(loc.responses)] < 0):
            continue
        a, b = (names[i] for i in loc.responses)
        out.append(f"{f.location} is the sum of {a} and {b}: the data cannot fix their signs against each other, "
                   f"so it is the relative motion between them (an interface) if one of the two sensors reads the "
                   f"other way round, and their common motion if both read as recorded; the mounting tells which")
    return out


def _by_gain(c: Candidate) -> float:
    """Sort key: the largest held-out gain first, a candidate without one (diverged, failed) last."""
    return -c.gain if np.isfinite(c.gain) else np.inf


def _linear_corrections(comp_scored: list[Candidate], settings: Settings) -> list[str]:
    """The best compensated candidate that ``significant`` turned down only because its own spring and
    damper alone predict better than the baseline: a person should know that the fitted linear part is
    off there, and that the cause on top of its correction is not a finding."""
    held = [c for c in comp_scored if np.isfinite(c.gain) and not significant(c, settings) and c.own_gain < c.gain
            and significant(replace(c, own_gain=max(c.own_gain, c.gain), own_p=0.0), settings)]
    if not held:
        return []
    c = max(held, key=lambda c: c.gain)
    return [f"{c.label}, regressed with a spring and a damper at its coordinate, would gain {c.gain:.2g} on "
            f"held-out blocks, but that spring and damper alone already predict better than the baseline: "
            f"a correction of the fitted linear part with a cause on top, not a finding"]


def _engaged_aside(scored: list[Candidate], findings: list[Candidate], char: dict, settings: Settings) -> list[str]:
    """The significant stopper engaged throughout (``engaged_throughout``) with the largest held-out gain,
    when it gains more than the first finding (or there is none): said, with why it is no finding."""
    aside = [c for c in scored if engaged_throughout(c, char) and significant(c, settings)]
    if not aside:
        return []
    best = max(aside, key=lambda c: c.gain)
    if findings and best.gain <= findings[0].gain:
        return []
    share = best.parameters["gap"] / _largest_displacement(char, best.location)
    return [f"{best.label} (held-out gain {best.gain:.2f}) was set aside: its gap is {share:.0%} of the largest "
            "displacement there, so it is engaged through nearly all of the motion, a linear spring more than a "
            "stopper"]


def _set_aside(scored: list[Candidate], findings: list[Candidate]) -> list[str]:
    """The candidate with the largest held-out gain that the fit record's check set aside, when it gains
    more than the first finding (or there is none): a person reading the answer should know that the
    analysed record alone favoured it, and why it is not the answer."""
    aside = [c for c in scored if c.note.startswith(FIT_BREAK) and np.isfinite(c.gain)]
    if not aside:
        return []
    best = max(aside, key=lambda c: c.gain)
    if findings and best.gain <= findings[0].gain:
        return []
    return [f"{best.label} (held-out gain {best.gain:.2f} on this record) was set aside: {best.note}"]


def _select(scored: list[Candidate], baseline: Baseline, prep: Prepared, split: Split, sc: Scoring,
            settings: Settings, char: dict) -> Selection:
    first, alike, why = choose(scored, settings)
    if first is None:
        return Selection([], [], [why])
    # the record's own backbone may settle look-alikes before a second finding is sought on top of the first
    first, alike, settled = _settle_by_backbone(first, alike, scored, prep, char, settings)
    alike = _softening_look_alike(first, alike, scored, settings) + alike  # first, so the verdict names it
    reasons = [settled] if settled else []
    findings, ambiguous = [first], [alike]
    # a second finding: another cause at another location adding a significant gain on top of the first,
    # tested over whole blocks (``clustered_p``): a piece-level test let a 0.03 gain through (seed 2)
    own = first.baseline or baseline
    taken = {first.label} | {a.label for a in alike}
    rest = [c for c in scored if c.label not in taken and significant(c, settings) and c.elements
            and c.location != first.location][:4]
    best2, counts = None, pieces_per_block(split.test, sc.piece)
    for c in rest:
        if any(el.gain.size != own.model.poles.size for el in c.elements):
            continue  # fitted with a linear part of another order (``fit_jointly``'s extra mode): no sum
        model = own.model.with_elements(first.elements + c.elements)
        errs, nrmse = block_errors(own, model, prep, split.test, sc.warm, sc.scale, first.output + c.output,
                                   sc.bound, sc.piece)
        p = clustered_p(first.block_errors, errs, counts)
        gain = 1.0 - nrmse / first.test_nrmse if np.isfinite(nrmse) else -np.inf
        if p < settings.alpha and gain > settings.gain_floor and (best2 is None or gain > best2[0]):
            best2 = (gain, c)
    if best2 is not None:
        findings.append(best2[1])
        ambiguous.append([])
    return Selection(findings, ambiguous, reasons)
