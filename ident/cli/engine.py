"""Independent cases as Dask tasks (``dask.distributed``): the cluster behind ``--scheduler`` and ``--workers``.

The science stays where it is: a case is a module-level function and its argument (both pickled to the
workers, which import this package), and this module only decides where it runs.

- ``--scheduler ADDRESS`` (``tcp://HOST:8786``): a running cluster's scheduler: SLURM through dask-jobqueue,
  Kubernetes through dask-kubernetes, ``dask scheduler`` and ``dask worker`` by hand. Its workers need this
  package installed and the input files at the same paths (a shared file system).
- ``--workers N``: a local cluster of N worker processes of one thread each, bound to 127.0.0.1 (scheduler,
  nannies and workers listen on this machine only) and without dashboards. The compiled kernels' threads are
  split between the workers (``NUMBA_NUM_THREADS`` = cores / N), so N workers do not oversubscribe the
  cores. The workers are started with Ctrl-C ignored: the command that started them handles the interrupt
  (keeps its finished results, cancels the rest) and closes them.

:func:`run_ordered` yields the results in the order of the cases as soon as each prefix is complete, so a
command prints exactly what its serial loop prints; :func:`run_unordered` yields them as they finish.

Same results wherever a case runs: every case, in this process or on a worker, runs with the linear
algebra (BLAS) on one thread (:class:`OneBlasThread`). A multithreaded BLAS splits its sums by thread
count, so the last digits of a least-squares solution depended on it, and through the sweep's selection
and the SQP refinement the 10th digit of a natural frequency did (seen: 3.579502860395579 Hz in this
process, 3.5795028609967976 Hz on a worker). The compiled kernels' thread count does not change results
(each model of a batch is integrated by one thread).
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any

import dask
from distributed import Client, LocalCluster, as_completed
from threadpoolctl import threadpool_limits

from . import number

CONNECT_TIMEOUT_S = 20
WORKERS = number(0, 1024, integer=True)


def add_options(p, workers_help: str) -> None:
    """``--scheduler ADDRESS`` and ``--workers N`` on a (sub)command's parser."""
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the cases as Dask tasks on the scheduler at ADDRESS (tcp://HOST:8786), e.g. a "
                        "SLURM cluster through dask-jobqueue; its workers must see the same files")
    p.add_argument("--workers", type=WORKERS, help=workers_help)


def cores() -> int:
    return os.cpu_count() or 1


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """Ctrl-C ignored while the local workers are spawned (they inherit it); the caller's handler after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _spawn_environ() -> dict:
    """distributed's variables for a worker process before it starts, less ``MALLOC_TRIM_THRESHOLD_``.

    distributed sets it to 64 KiB so that workers hand freed memory back to the system. Set at all, it
    also turns off glibc's dynamic mmap threshold, so every array above 128 KiB is mapped afresh and its
    pages faulted in again: the same discovery case took 14-16 s on a worker or with the variable set in
    a plain process, 5 s without it (independent seed 10, stop 35). The variable's absence is what
    restores glibc's default; a value cannot."""
    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", default={}) or {})
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return environ


def local_cluster(n_workers: int) -> LocalCluster:
    """N worker processes on this machine, one thread each, listening on 127.0.0.1 only, no dashboard,
    with glibc's own memory allocation (``_spawn_environ``)."""
    if n_workers < 1:
        raise ValueError(f"a local cluster needs at least one worker, got {n_workers}")
    numba_threads = max(1, cores() // n_workers)
    with _sigint_ignored(), dask.config.set({"distributed.nanny.pre-spawn-environ": _spawn_environ()}):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                            dashboard_address=None, worker_dashboard_address=None, silence_logs=logging.ERROR,
                            # no dashboard; the scheduler's small HTTP server (health, metrics) on a free port
                            # of 127.0.0.1 rather than 8787, which another cluster may hold
                            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                            env={"NUMBA_NUM_THREADS": str(numba_threads)})


@contextmanager
def dask_client(scheduler: str | None, workers: int | None) -> Iterator[Client]:
    """A client of the scheduler at ``scheduler``, or of a local cluster of ``workers`` processes (default:
    one per core), closed (with the local cluster) when the block ends."""
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            text = " ".join(str(exc).split()) or type(exc).__name__
            raise ValueError(f"--scheduler {scheduler}: cannot connect ({text})") from None
        try:
            yield client
        finally:
            client.close()
        return
    cluster = local_cluster(workers or cores())
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


class OneBlasThread:
    """``func(job)`` with BLAS on one thread (picklable, so it is the task Dask sends)."""

    def __init__(self, func: Callable):
        self.func = func

    def __call__(self, job):
        with threadpool_limits(limits=1, user_api="blas"):
            return self.func(job)


def _submit(client: Client, func: Callable, jobs: Sequence, name: str) -> tuple[list, dict]:
    tag = f"{name}-{uuid.uuid4().hex[:8]}"
    futures = client.map(OneBlasThread(func), list(jobs), key=[f"{tag}-{i}" for i in range(len(jobs))], pure=False)
    return futures, {f.key: i for i, f in enumerate(futures)}


def run_unordered(client: Client, func: Callable, jobs: Sequence, name: str = "case") -> Iterator[tuple[int, Any]]:
    """``(index, func(jobs[index]))`` as the tasks finish; a task's exception is raised here. Leaving the
    loop early (an exception, Ctrl-C) cancels the tasks not yet finished."""
    futures, index = _submit(client, func, jobs, name)
    pending = set(futures)
    try:
        for fut in as_completed(futures, loop=client.loop):
            pending.discard(fut)
            result = fut.result()
            fut.release()
            yield index[fut.key], result
    finally:
        if pending:
            client.cancel(list(pending))


def run_ordered(client: Client, func: Callable, jobs: Sequence, name: str = "case") -> Iterator[Any]:
    """``func(job)`` for every job, in the order of ``jobs``, each as soon as it and all before it are done."""
    done: dict[int, Any] = {}
    nxt = 0
    for i, result in run_unordered(client, func, jobs, name):
        done[i] = result
        while nxt in done:
            yield done.pop(nxt)
            nxt += 1


def mapper(client: Client | None, name: str = "case") -> Callable[[Callable, Sequence], Iterator[Any]]:
    """``map(func, jobs)`` on the cluster (or in this process without a client): what a pure science loop
    takes as its ``mapper``."""
    return lambda func, jobs: ordered(client, func, list(jobs), name)


@contextmanager
def session(scheduler: str | None, workers: int | None) -> Iterator[Client | None]:
    """The client the options ask for: None (run in this process) without ``--scheduler`` and with no or 0
    ``--workers``; else a client of the scheduler or of a local cluster of that many workers."""
    if scheduler and workers is not None:
        raise ValueError("give --scheduler ADDRESS (a running cluster) or --workers N (a local one), not both")
    if not scheduler and not workers:
        yield None
        return
    with dask_client(scheduler, workers) as client:
        yield client


def unordered(client: Client | None, func: Callable, jobs: Sequence, name: str = "case") -> Iterator[tuple[int, Any]]:
    """:func:`run_unordered` on the client, or a plain loop in this process without one."""
    if client is None:
        one = OneBlasThread(func)
        return ((i, one(job)) for i, job in enumerate(jobs))
    return run_unordered(client, func, jobs, name)


def ordered(client: Client | None, func: Callable, jobs: Sequence, name: str = "case") -> Iterator[Any]:
    """:func:`run_ordered` on the client, or ``map`` in this process without one."""
    if client is None:
        return map(OneBlasThread(func), jobs)
    return run_ordered(client, func, jobs, name)
