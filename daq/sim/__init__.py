"""daq.sim: simulated devices.

``independent``: a higher-fidelity simulator of rigs and structures (finite-element beams, a force-excited
Duffing oscillator, a chain of masses) written apart from ``ident``: it imports nothing from ``ident``, so
the science can be judged on data its own model did not make.
"""
