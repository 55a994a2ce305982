"""daq.sim.independent: a data generator written from physics, apart from ``ident`` (it imports nothing
from it), of higher fidelity than the models the science assumes, so that the science can be judged on
data its own model did not make.
"""
