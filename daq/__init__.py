"""daq: acquisition of the shaker rig's three accelerometers.

The serial frame protocol (pure decoder), the simulated rig as a device
(pty server and pyserial ``rig://`` handler), the driver that owns the port,
and the sinks (MCAP recorder). May import ident; never replay.
"""

import os

# numpy picks its SIMD kernels by the CPU, and its AVX-512 kernels round some results differently from the
# AVX2 ones (x86-64 level 3, what nearly every x86 machine of the last decade has); discovery's optimisers
# follow such differences to other answers (independent seed 42: "nothing" with numpy's AVX-512 kernels, the
# chain's cubic named right with the AVX2 ones; seed 45's baseline keeps or drops a pole). So numpy is held
# to the AVX2 kernels wherever this package or ``ident`` is imported before numpy, and the processes they
# start inherit it. Setting NPY_DISABLE_CPU_FEATURES yourself (even to "") chooses otherwise.
NUMPY_SIMD_PIN = "X86_V4 AVX512_ICL AVX512_SPR"
os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", NUMPY_SIMD_PIN)

# OpenBLAS, numpy's and scipy's linear algebra, picks its kernels by the CPU as well: on an AVX-512 machine
# its SkylakeX ones, whose sums round otherwise than its Haswell (AVX2) ones (an AMD machine without AVX-512
# runs its Zen set, built on those). Independent seed 116 (nothing hidden) had a false quadratic damping
# named with the SkylakeX kernels, "nothing" with the Haswell ones (stop 73: 1 of 14 "none" cases found
# something on such a host). So OpenBLAS is held to its Haswell kernels where the CPU has AVX2 and FMA
# (forced on a CPU without them, it would stop at an illegal instruction); setting OPENBLAS_CORETYPE
# yourself chooses otherwise. ``ident`` carries the same lines: it cannot import daq, and daq does not
# import ident's 1.2 s of modules to share seven lines (a test checks they agree).
BLAS_PIN = "Haswell"


def _has_avx2() -> bool:
    try:
        with open("/proc/cpuinfo") as fh:
            flags = next((line.split(":", 1)[1].split() for line in fh if line.startswith("flags")), [])
    except OSError:
        return False
    return "avx2" in flags and "fma" in flags


if _has_avx2():
    os.environ.setdefault("OPENBLAS_CORETYPE", BLAS_PIN)
