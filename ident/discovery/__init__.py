"""Discovery: what a model of a vibrating structure gets wrong in measured data, the cause, the extended
model and its gain on held-out data. One design (see ``discover`` for the flow):

- ``signals``: measured data as recorded, the band, signs and kinematics;
- ``catalogue``: the causes as data, each force law compiled once;
- ``model``: a modal linear part plus nonlinear elements, and its integrator;
- ``baselines``: the rig model from a config, or a modal model fitted to the data, behind one interface;
- ``characterise``: restoring-force curves per location (detection and characterisation);
- ``search``: regression, refinement by simulation, held-out scoring, honest selection;
- ``split``: interleaved held-out blocks, and the transients an unmeasured input leaves;
- ``result``: the ``Discovery`` and its JSON.
"""

from .discover import discover
from .result import Discovery, to_json
from .search import Settings
from .signals import Channel, Measurement

__all__ = ["discover", "Discovery", "to_json", "Settings", "Channel", "Measurement"]
