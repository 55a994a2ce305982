"""Play samples through the live pipeline, paced in recorded time or as fast as possible.

Pacing is against absolute deadlines: block k is released at
wall_start + (t_k - t_start) / rate, computed from the start, never by
sleeping "one block" after the previous one, so lateness does not accumulate
(python-can issue 1372). ``rate=None`` plays as fast as the pipeline allows.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from ident.live.pipeline import Pipeline, PipelineConfig, StepOutput, rolling_config
from ident.live.regimes import RegimeConfig

from .formats.base import Samples


@dataclass
class PlayReport:
    samples: int = 0
    blocks: int = 0
    wall_s: float = 0.0
    stream_s: float = 0.0
    max_late_s: float = 0.0  # worst lateness of a block against its deadline
    loops: int = 0


def play(samples: Samples, *, rate: float | None = 1.0, start_s: float = 0.0, duration_s: float | None = None,
         loop: bool = False, identify: bool = True, on_step: Callable[[StepOutput], None] | None = None,
         stop: Callable[[], bool] | None = None, max_loops: int | None = None, window_s: float = 4.0,
         hop_s: float = 1.0, gaps: tuple[float, float] | None = None,
         regime_window_s: float = RegimeConfig.window_s) -> PlayReport:
    if rate is not None and not 0 < rate <= 1e6:
        raise ValueError(f"--rate must be a positive, finite speed, got {rate}")
    pipe = Pipeline(PipelineConfig(fs_hz=samples.fs_hz, identify=identify,
                                   rolling=rolling_config(samples.fs_hz, window_s, hop_s),
                                   regime=RegimeConfig(fs_hz=samples.fs_hz, gap_m=gaps, window_s=regime_window_s)))
    rep = PlayReport()
    wall0 = time.monotonic()
    offset = 0.0  # stream time already played in earlier loops
    block_s = 0.05 if rate is not None else 0.5  # as fast as possible: fewer, larger blocks
    while True:
        t_first = None
        for t, vals in samples.blocks(start_s, duration_s, block_s):
            if t_first is None:
                t_first = t[0]
            t_end = offset + (t[-1] - t_first) + 1.0 / samples.fs_hz
            if rate is not None:
                deadline = wall0 + t_end / rate
                wait = deadline - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                else:
                    rep.max_late_s = max(rep.max_late_s, -wait)
            out = pipe.step(vals)
            if on_step is not None:
                on_step(out)
            rep.samples += len(vals)
            rep.blocks += 1
            rep.stream_s = t_end
            if stop is not None and stop():
                loop = False
                break
        rep.loops += 1
        offset = rep.stream_s
        if not loop or (max_loops is not None and rep.loops >= max_loops):
            break
    out = pipe.finish()  # the last window's refined fit
    if on_step is not None:
        on_step(out)
    rep.wall_s = time.monotonic() - wall0
    return rep
