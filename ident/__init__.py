"""ident: sparse identification of nonlinear dynamics for a forced vibration rig.

Pure science: arrays in, arrays and dataclasses out. Follows "Reconstruction of
Governing Equations from Vibration Measurements for Geometrically Nonlinear
Systems" (Lubricants 2019, 7(8), 64): forcing appended to the library (eq. 7),
delay embedding, TVRegDiff derivatives, a sparsity sweep chosen by integration
error and SQP refinement (Stender et al. 2019). The only I/O lives in ident.cli.
"""

import os

# numpy held to its AVX2 kernels before it is imported, as ``daq`` does (daq/__init__.py says why; this is
# the same value, which a test checks: ident cannot import daq)
NUMPY_SIMD_PIN = "X86_V4 AVX512_ICL AVX512_SPR"
os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", NUMPY_SIMD_PIN)
# and OpenBLAS to its Haswell kernels where the CPU has AVX2 and FMA, as ``daq`` does (the same value)
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

from .library import PolynomialForcingLibrary  # noqa: E402 - after the pin
from .model import SindyModel  # noqa: E402
from .sindy import Identification, identify, refine, stlsq, sweep  # noqa: E402
from .simulate import simulate  # noqa: E402

__all__ = ["PolynomialForcingLibrary", "SindyModel", "Identification", "identify", "refine",
           "stlsq", "sweep", "simulate"]
