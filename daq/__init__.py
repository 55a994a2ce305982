"""daq: acquisition of the shaker rig's three accelerometers.

The serial frame protocol (pure decoder), the simulated rig as a device
(pty server and pyserial ``rig://`` handler), the driver that owns the port,
and the sinks (MCAP recorder). May import ident; never replay.
"""
