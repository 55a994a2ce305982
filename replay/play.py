"""Play samples through the live pipeline, paced in recorded time or as fast as possible.

Pacing is against absolute deadlines: block k is released at
wall_start + (t_k - t_start) / rate, computed from the start, never by
sleeping "one block" after the previous one, so lateness does not accumulate
(python-can issue 1372). ``rate=None`` plays as fast as the pipeline allows.

As fast as possible, the rolling identification may run in a second process (``RemoteIdentifier``):
it fits block k while this process filters, monitors and writes the blocks after it, and its fits come
``LAG_BLOCKS`` blocks behind. They are the same fits, bit for bit, in the same order (the identifier
sees the same blocks); only the step that carries them moves.
"""

from __future__ import annotations

import multiprocessing
import queue
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ident.live.pipeline import Pipeline, PipelineConfig, StepOutput, rolling_config, warm_up
from ident.live.regimes import RegimeConfig
from ident.live.rolling import RollingConfig, RollingIdentifier, WindowFit

from .formats.base import Samples


@dataclass
class PlayReport:
    samples: int = 0
    blocks: int = 0
    wall_s: float = 0.0
    stream_s: float = 0.0
    max_late_s: float = 0.0  # worst lateness of a block against its deadline
    loops: int = 0


LAG_BLOCKS = 8  # blocks the second process may fall behind: a window's fit (every hop) is a burst of work


def _serve(blocks, results, cfg: RollingConfig) -> None:
    """The second process: a RollingIdentifier fed blocks from one queue, its fits put on the other
    ("ready" once its kernels are loaded; per block the fits it completes; None asks for ``finish``).
    Ctrl-C is the parent's to handle; it ends when the parent does."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        warm_up(identify=True)
        ident = RollingIdentifier(cfg)
    except Exception as exc:  # noqa: BLE001 - handed to the parent, which raises it as its own
        results.put(("error", exc, 0.0))
        return
    cpu0 = time.process_time()
    results.put(("ready", None, 0.0))
    parent = multiprocessing.parent_process()
    while True:
        try:
            block = blocks.get(timeout=1.0)
        except queue.Empty:
            if parent is not None and not parent.is_alive():
                return
            continue
        if isinstance(block, str):  # "stop": the parent leaves without the rest
            return
        try:
            out = ident.finish() if block is None else ident.step(block)
        except Exception as exc:  # noqa: BLE001 - handed to the parent, which raises it as its own
            results.put(("error", exc, time.process_time() - cpu0))
            return
        results.put(("fits", out, time.process_time() - cpu0))
        if block is None:
            return


class RemoteIdentifier:
    """The rolling identification in a second process, for ``Pipeline(identifier=...)``: ``step(block)``
    hands the block over and returns the fits of the block ``lag`` blocks before it (waiting for them),
    so that the second process works through a window's fit while this one goes on; ``finish()`` returns
    the rest. The blocks and fits travel on queues (their feeder threads write, so neither side blocks
    the other). Start it before the clock: the process loads numpy, scipy and the compiled kernels
    (about a second from numba's cache), and ``ready()`` waits for that. A context manager: leaving it
    ends the process."""

    def __init__(self, cfg: RollingConfig, lag: int = LAG_BLOCKS):
        ctx = multiprocessing.get_context("spawn")  # not fork: numba's threads must not be copied
        self._blocks, self._results = ctx.Queue(), ctx.Queue()
        self._proc = ctx.Process(target=_serve, args=(self._blocks, self._results, cfg), daemon=True,
                                 name="rolling-identification")
        self._proc.start()
        self.cfg = cfg
        self.lag = max(0, int(lag))
        self._pending = 0  # blocks handed over whose fits are not yet back
        self._ready = False
        self.cpu_s = 0.0  # CPU seconds the process has spent on blocks (its start-up not counted)

    def _receive(self) -> list[WindowFit]:
        while True:
            try:
                kind, value, self.cpu_s = self._results.get(timeout=1.0)
                break
            except queue.Empty:
                if not self._proc.is_alive() and self._results.empty():
                    raise RuntimeError("the rolling identification's process ended unexpectedly") from None
        if kind == "error":
            raise value
        return value

    def ready(self) -> None:
        if not self._ready:
            self._receive()
            self._ready = True

    def step(self, block: np.ndarray) -> list[WindowFit]:
        self.ready()
        self._blocks.put(np.asarray(block, float))
        self._pending += 1
        if self._pending <= self.lag:
            return []
        self._pending -= 1
        return self._receive()

    def finish(self) -> list[WindowFit]:
        self.ready()
        self._blocks.put(None)
        out = []
        for _ in range(self._pending + 1):
            out += self._receive()
        self._pending = 0
        return out

    def close(self) -> None:
        if self._proc.is_alive():
            self._blocks.put("stop")
        self._blocks.close()
        self._proc.join(timeout=5.0)
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join()
        self._results.close()

    def __enter__(self) -> RemoteIdentifier:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def play(samples: Samples, *, rate: float | None = 1.0, start_s: float = 0.0, duration_s: float | None = None,
         loop: bool = False, identify: bool = True, on_step: Callable[[StepOutput], None] | None = None,
         stop: Callable[[], bool] | None = None, max_loops: int | None = None, window_s: float = 4.0,
         hop_s: float = 1.0, gaps: tuple[float, float] | None = None,
         regime_window_s: float = RegimeConfig.window_s, identifier=None) -> PlayReport:
    """``identifier``: where the rolling identification runs (default: in this process), e.g. a
    ``RemoteIdentifier(rolling_config(samples.fs_hz, window_s, hop_s))``."""
    if rate is not None and not 0 < rate <= 1e6:
        raise ValueError(f"--rate must be a positive, finite speed, got {rate}")
    pipe = Pipeline(PipelineConfig(fs_hz=samples.fs_hz, identify=identify,
                                   rolling=rolling_config(samples.fs_hz, window_s, hop_s),
                                   regime=RegimeConfig(fs_hz=samples.fs_hz, gap_m=gaps, window_s=regime_window_s)),
                    identifier=identifier)
    rep = PlayReport()
    wall0 = time.monotonic()
    offset = 0.0  # stream time already played in earlier loops
    block_s = 0.05 if rate is not None else 2.0  # as fast as possible: fewer, larger blocks
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
