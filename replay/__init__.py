"""replay: recordings after the fact: formats (one module per format, one suffix table), paced playback
through the live pipeline, recovery of damaged files, and the ``replay`` command.

May import ident and daq.
"""

# first: holds numpy to its AVX2 kernels before anything here imports numpy (daq/__init__.py says why)
from daq import NUMPY_SIMD_PIN

__all__ = ["NUMPY_SIMD_PIN"]
