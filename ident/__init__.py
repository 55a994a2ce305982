"""ident: sparse identification of nonlinear dynamics for a forced vibration rig.

Pure science: arrays in, arrays and dataclasses out. Follows "Reconstruction of
Governing Equations from Vibration Measurements for Geometrically Nonlinear
Systems" (Lubricants 2019, 7(8), 64): forcing appended to the library (eq. 7),
delay embedding, TVRegDiff derivatives, a sparsity sweep chosen by integration
error and SQP refinement (Stender et al. 2019). The only I/O lives in ident.cli.
"""

from .library import PolynomialForcingLibrary
from .model import SindyModel
from .sindy import Identification, identify, refine, stlsq, sweep
from .simulate import simulate

__all__ = ["PolynomialForcingLibrary", "SindyModel", "Identification", "identify", "refine",
           "stlsq", "sweep", "simulate"]
