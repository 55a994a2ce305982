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
