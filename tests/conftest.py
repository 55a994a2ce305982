"""Shared fixtures: the paper's clean Duffing data, computed once per session."""

import os

# One BLAS thread a worker: the suite runs three workers on two cores (pyproject's ``-n 3``), and OpenBLAS's
# threads wait for each other by spinning (stop 84, a 2-core host, numba's cache warm, one run each: two threads
# a worker 632 s and 20.1 CPU-minutes, one 522 s and 16.3; the paper study's setup 33 -> 22 s; runs of the same
# code on that host varied by 10 % or more, so this is likely, not settled). Discovery holds itself to one
# thread already (``discover``); the commands the tests start inherit this.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from daq import NUMPY_SIMD_PIN  # before numpy: holds it to its AVX2 kernels, as the commands do (daq/__init__.py)

os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", NUMPY_SIMD_PIN)  # (daq's import has set it already)

import numpy as np  # noqa: E402
import pytest


def pytest_configure(config):
    """No usage analytics from rerun while tests run (the machines have no network for it)."""
    import shutil
    import subprocess
    import sys

    exe = shutil.which("rerun") or os.path.join(os.path.dirname(sys.executable), "rerun")
    if os.path.exists(exe):
        subprocess.run([exe, "analytics", "disable"], capture_output=True, timeout=60)


# The files that take longest, longest first (per-file sums of ``--durations`` on a 2-core host, stop 81:
# the independent discovery cases with a test of their own 463 s in one file, the rest 144 s and less; that
# file alone set the run's 473 s, so it is three files now, one theme each, of 145-175 s). ``--dist loadfile``
# with ``--no-loadscope-reorder`` (pyproject) hands whole files to the workers in collection order, so these
# start at once and the short files fill in at the end; xdist's default order (files with the most tests
# first) started the three discovery files of nine tests each in the middle of the run. Files not listed keep
# their order. The three files that start are not two discovery files: on a fresh clone numba's cache is
# empty, and two workers that start on discovery both compile its kernels at once. One starts on discovery,
# one on the live pipeline's kernels (``replay``), one on the paper's study (``cli``: SINDy's); each compiles
# its own and later loads the others' from the cache.
LONGEST_FIRST = ("test_discovery_independent_seeds.py", "test_replay.py", "test_cli.py",
                 "test_discovery_independent_transients.py", "test_discovery_independent_lookalikes.py",
                 "test_discovery_parts.py", "test_discovery_independent.py", "test_discovery_rates.py",
                 "test_discovery.py", "test_independent_generator.py", "test_record.py", "test_bounded_inputs.py",
                 "test_regimes.py", "test_protocol.py", "test_modal_fit_independent.py", "test_engine.py",
                 "test_duffing.py", "test_batch.py", "test_viewer_blueprint.py")


def pytest_collection_modifyitems(items):
    """Longest files first (``LONGEST_FIRST``); a stable sort, so each file's own order stays."""
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture(scope="session")
def duffing():
    from ident.paper.duffing import duffing_data

    return duffing_data()


@pytest.fixture(scope="session")
def lorenz():
    """Lorenz-63 (sigma 10, rho 28, beta 8/3) on its attractor, dt = 0.002, tight tolerance."""
    from scipy.integrate import solve_ivp

    def rhs(t, u):
        return [10 * (u[1] - u[0]), u[0] * (28 - u[2]) - u[1], u[0] * u[1] - 8 / 3 * u[2]]

    t = np.arange(0, 30, 0.002)
    sol = solve_ivp(rhs, (0, 30), [-8, 8, 27], t_eval=t, method="DOP853", rtol=1e-12, atol=1e-12)
    x = sol.y.T
    dx = np.array([rhs(0, u) for u in x])
    return t, x, dx


@pytest.fixture(scope="session")
def dask_scheduler():
    """The address of a local Dask cluster of 2 worker processes (ident.cli.engine's, on 127.0.0.1), started once
    for the tests that run cases as Dask tasks and pass it as ``--scheduler``."""
    from ident.cli.engine import local_cluster

    cluster = local_cluster(2)
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()
