"""``ident bench sweep|discovery|batch|memory|f16``: the benchmarks (printed figures, not tests).

``discovery`` is ``ident.cli.bench_discovery`` (hidden-effect cases, on Dask with ``--workers`` or
``--scheduler``), ``batch`` is ``ident.cli.bench_batch`` (``ident batch`` on 1 and 2 local workers),
``memory`` is ``ident.cli.bench_memory`` (``discover`` on a long record within its memory budget and
without), ``f16`` is ``ident.cli.bench_f16`` (``discover`` on the F-16 records and the resonance its answer
predicts). Here:
``sweep``, this project's sparsification sweep against a plain pysindy loop.

Both run the same job on the paper's Table 2 data (Duffing, noise eta = 0.08
on X and Xdot, states denoised as ``ident duffing`` does; on clean data every
threshold below 1e-15 gives an exact model and the choice says nothing): for
each threshold, fit
STLSQ, integrate the model with the measured forcing, score the integration
error, keep the best. Ours integrates all candidates in one compiled batch;
the baseline calls pysindy's ``SINDy.fit`` and ``SINDy.simulate`` per
threshold. Prints both times, their ratio, and whether both chose the same
active set. A benchmark, not a test: the ratio is the figure that holds on a
noisy machine. Run it alone: the compiled kernel uses both cores.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from daq.sim.independent.cases import FAMILY_CAUSES

from ..derivatives import smooth
from ..library import PolynomialForcingLibrary
from ..paper.duffing import denoise_window, duffing_data
from ..sindy import sweep
from . import DURATION, RATE_HZ, SEED, number
from .bench_batch import run_bench as run_batch_bench
from .bench_discovery import RIG_CASE_S, run_discovery
from .bench_f16 import run_bench as run_f16_bench
from .bench_memory import run_bench as run_memory_bench
from .engine import add_options


TOLERANCE = 0.5  # the same selection rule as ident.sindy.sweep's default


def add_parser(sub) -> None:
    p = sub.add_parser("bench", help="benchmarks (printed ratios, not tests)")
    p.add_argument("what", choices=["sweep", "discovery", "batch", "memory", "f16"],
                   help="sweep: ours vs a pysindy fit+simulate loop; discovery: hidden-effect cases; batch: "
                        "ident batch in this process and on 1 and 2 local Dask workers; memory: discover on a long "
                        "record within its memory budget and as recorded; f16: discover on the F-16 ground "
                        "vibration test and the resonance its answer predicts")
    p.add_argument("--data", type=Path,
                   help="f16: the F-16 benchmark's folder (default ../shared/data/f16_gvt)")
    p.add_argument("--cases", type=number(1, 100_000, integer=True), default=100,
                   help="discovery: number of seeded cases (default 100)")
    p.add_argument("--generator", choices=("independent", "rig"), default="independent",
                   help="discovery: daq.sim.independent (written apart from ident; default) or daq.sim.hidden "
                        "(this project's rig model with one effect)")
    p.add_argument("--seed", type=SEED, default=0, help="discovery: first seed; batch: the campaign's seed")
    p.add_argument("--family", choices=sorted(FAMILY_CAUSES),
                   help="discovery (independent generator): this family on every seed instead of the family drawn "
                        "(duffing_softening, a Duffing oscillator with a softening cubic, is run only when asked for)")
    p.add_argument("--twins", action="store_true",
                   help="discovery (independent generator): also run each case without its effect: the findings "
                        "made where there is nothing, and each effect's share of the baseline's error")
    p.add_argument("--save", type=Path, metavar="OUT.jsonl",
                   help="discovery: also write each case's truth, verdict and discover's JSON (every candidate) as "
                        "a line of OUT.jsonl, for studies without running the cases again (never replaces a file)")
    p.add_argument("--resume", action="store_true",
                   help="discovery with --save: continue the run cut short whose OUT.jsonl.part is there: its whole "
                        "lines are kept, only the cases it lacks are run, and the report covers them all")
    p.add_argument("--duration", type=DURATION, help=f"discovery: the rig generator's case length (default "
                                                       f"{RIG_CASE_S:g} s); batch: each recording's (default 8 s); "
                                                       "memory: the record's (default 120 s)")
    p.add_argument("--fs", type=RATE_HZ, dest="fs_hz", help="memory: the record's sampling rate (default 10 kHz)")
    p.add_argument("--max-samples", type=number(1000, integer=True),
                   help="memory: the budget of the first run (default a quarter of the record's samples x responses)")
    p.add_argument("--campaign", type=Path, help="batch: the campaign's folder (made there if missing or empty, "
                                                 "reused after; default: a temporary folder)")
    p.add_argument("--recordings", type=number(2, 100_000, integer=True), default=100,
                   help="batch: recordings in the campaign (default 100, and one cut copy)")
    add_options(p, "discovery: local Dask worker processes (default: in this process, one case after another)")
    p.add_argument("--max-baseline", type=int, default=0,
                   help="run pysindy on at most this many thresholds and extrapolate (0 = all)")
    p.set_defaults(func=run)


def _pysindy_loop(x, xdot, t, f, lambdas, n_rows):
    import warnings

    import pysindy as ps

    lib = ps.GeneralizedLibrary(
        [ps.PolynomialLibrary(degree=3), ps.IdentityLibrary()], inputs_per_library=[[0, 1], [2]]
    )
    errs, sets = [], []
    for lam in lambdas:
        # pysindy normalises columns by their L2 norm, ours by RMS: same threshold times sqrt(N).
        model = ps.SINDy(optimizer=ps.STLSQ(threshold=lam * np.sqrt(n_rows), alpha=0.0,
                                            normalize_columns=True), feature_library=lib)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model.fit(x, t=t, x_dot=xdot, u=f[:, None], feature_names=["x1", "x2", "F"])
            coef = model.coefficients()
            try:
                # pysindy drops the last sample when it interpolates u; score what it returns
                sim = model.simulate(x[0], t, u=f[:, None])
                e = np.mean(np.sqrt(np.mean((sim - x[: sim.shape[0]]) ** 2, axis=0)) / x.std(axis=0))
                if sim.shape[0] < x.shape[0] - 1 or not np.isfinite(e):
                    e = np.inf
            except Exception:  # noqa: BLE001 - a failed candidate is scored, as in our sweep
                e = np.inf
        errs.append(e)
        sets.append(coef != 0)
    return np.array(errs), sets


def run(args) -> int:
    if args.save is not None and args.what != "discovery":
        raise ValueError("--save keeps the discovery benchmark's records; it is for ident bench discovery")
    if args.resume and args.what != "discovery":
        raise ValueError("--resume continues an ident bench discovery --save run; it is for ident bench discovery")
    if args.family is not None and args.what != "discovery":
        raise ValueError("--family picks the discovery benchmark's cases; it is for ident bench discovery")
    if args.data is not None and args.what != "f16":
        raise ValueError("--data is the F-16 records' folder; it is for ident bench f16")
    if args.what == "discovery":
        if args.duration is not None and args.generator != "rig":
            raise ValueError("--duration sets the rig generator's case length; the independent generator's cases "
                             "have their own")
        if args.family is not None and args.generator != "independent":
            raise ValueError("--family picks the independent generator's family; daq.sim.hidden has one rig")
        if args.twins and args.generator != "independent":
            raise ValueError("--twins needs the independent generator: daq.sim.hidden has no twins")
        return run_discovery(args.generator, args.cases, args.seed, args.workers, args.scheduler,
                             args.duration or RIG_CASE_S, args.twins, args.save, args.family, args.resume)
    if args.what != "memory" and (args.fs_hz is not None or args.max_samples is not None):
        raise ValueError("--fs and --max-samples are for ident bench memory")
    if args.what == "f16":
        return run_f16_bench(args.data or Path("../shared/data/f16_gvt"))
    if args.what == "memory":
        return run_memory_bench(args.duration or 120.0, args.fs_hz or 10_000.0, args.max_samples)
    if args.what == "batch":
        if args.scheduler or args.workers is not None:
            raise ValueError("ident bench batch compares 1 and 2 local workers itself; --scheduler and --workers "
                             "are for ident bench discovery")
        args.duration = args.duration or 8.0
        return run_batch_bench(args)
    return run_sweep(args)


def run_sweep(args) -> int:
    d = duffing_data()
    rng = np.random.default_rng([0, 8])
    xn = d.x + 0.08 * rng.standard_normal(d.x.shape)
    xd = d.xdot + 0.08 * rng.standard_normal(d.x.shape)
    x = smooth(xn, denoise_window(xn[:, 0]))
    lib = PolynomialForcingLibrary(2, 3)
    sweep(lib, x, xd, d.t, d.forcing)  # compile the kernel outside the timing
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        ours = sweep(lib, x, xd, d.t, d.forcing)
        times.append(time.perf_counter() - t0)
    t_ours = float(np.median(times))
    lambdas = ours.thresholds
    n_base = len(lambdas) if not args.max_baseline else min(args.max_baseline, len(lambdas))
    pick = np.linspace(0, len(lambdas) - 1, n_base).round().astype(int)
    t0 = time.perf_counter()
    errs, sets = _pysindy_loop(x, xd, d.t, d.forcing, lambdas[pick], x.shape[0])
    t_base = (time.perf_counter() - t0) * len(lambdas) / n_base
    ours_set = ours.coefficients[ours.chosen].T != 0
    finite = np.isfinite(errs)
    same = None
    if n_base == len(lambdas) and finite.any():
        best = np.min(errs[finite])
        ok = np.flatnonzero(finite & (errs <= best * (1 + TOLERANCE)))
        nnz = np.array([s.sum() for s in sets])
        base_set = sets[ok[np.argmin(nnz[ok])]]
        same = bool(np.array_equal(base_set, ours_set))
    print(f"candidates: {len(lambdas)} thresholds, {x.shape[0]} samples, library of {lib.n_terms} terms")
    print(f"this project : {t_ours:8.3f} s (median of 5)")
    extra = "" if n_base == len(lambdas) else f" (extrapolated from {n_base} thresholds)"
    print(f"pysindy loop : {t_base:8.3f} s{extra}")
    print(f"ratio        : {t_base / t_ours:8.0f} x faster")
    print(f"same active set chosen: {same if same is not None else 'not compared (partial baseline)'}")
    if same is not None:
        print("threshold  ours(nnz, error)        pysindy(nnz, error)")
        for lam, n1, e1, s2, e2 in zip(lambdas, ours.n_nonzero, ours.errors, sets, errs):
            print(f"{lam:9.3g}  {n1:3d} {e1:10.3g}          {int(s2.sum()):3d} {e2:10.3g}")
    return 0
