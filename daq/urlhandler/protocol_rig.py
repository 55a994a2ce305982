"""pyserial handler for ``rig://[?config=PATH][&seed=N][&realtime=1][&device_id=N][&calibrator=CH]``: the
simulated rig in process (``calibrator=tip1``: that sensor on a reference calibrator, 10 m/s^2 rms at
159.2 Hz, or ``tip1:HZ:RMS``).

Reads return the device's frames. With ``realtime=1`` they are paced by the
clock like the real line; by default a read returns as many frames as asked
for at once, for fast in-process tests. Modelled on pyserial's ``loop://``.
"""

from __future__ import annotations

import time
import urllib.parse

from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from ..calibration import CALIBRATOR_HZ, CALIBRATOR_RMS_M_PER_S2
from ..config import load_config
from ..sim.device import DEFAULT_DEVICE_ID, SimulatedDevice
from ..protocol import FRAME_LEN
from ..sim.sensors import CHANNELS

FAST_READ_FRAMES = 100  # frames a read finds waiting when not paced in real time


class Serial(SerialBase):
    def __init__(self, *args, **kwargs):
        self._device: SimulatedDevice | None = None
        self._pending = b""
        self._realtime = False
        self._t0 = 0.0
        super().__init__(*args, **kwargs)

    def open(self):
        if self._port is None:
            raise SerialException("Port must be configured before it can be used.")
        if self.is_open:
            raise SerialException("Port is already open.")
        self._device = self._from_url(self.portstr)
        self._t0 = time.monotonic()
        self.is_open = True

    def _from_url(self, url: str) -> SimulatedDevice:
        parts = urllib.parse.urlsplit(url)
        if parts.scheme != "rig":
            raise SerialException(f"expected rig://[?config=PATH&seed=N&realtime=1&device_id=N], got {url!r}")
        opts = {k: v[-1] for k, v in urllib.parse.parse_qs(parts.query).items()}
        unknown = set(opts) - {"config", "seed", "realtime", "device_id", "calibrator"}
        if unknown:
            raise SerialException(f"rig:// has no option {sorted(unknown)[0]!r}; options: config, seed, realtime, "
                                  f"device_id, calibrator")
        ints = {}
        for key in ("seed", "device_id"):
            if key in opts:
                try:
                    ints[key] = int(opts[key], 0)
                except ValueError:
                    raise SerialException(f"rig:// option {key} must be an integer, got {opts[key]!r}") from None
                if not 0 <= ints[key] < 2**32:
                    raise SerialException(f"rig:// option {key} must be from 0 to 2^32-1, got {opts[key]}")
        try:
            cfg = load_config(opts.get("config"))
        except ValueError as exc:
            raise SerialException(str(exc)) from None
        self._realtime = opts.get("realtime", "0") not in ("0", "false", "")
        return SimulatedDevice(cfg, ints.get("seed"), ints.get("device_id", DEFAULT_DEVICE_ID),
                               _calibrator(opts.get("calibrator")))

    def close(self):
        self.is_open = False
        self._device = None

    def _reconfigure_port(self):
        pass

    @property
    def in_waiting(self):
        if not self.is_open:
            raise PortNotOpenError()
        if not self._realtime and len(self._pending) < FRAME_LEN * FAST_READ_FRAMES:
            # as fast as possible: there is always a full read's worth of frames waiting
            self._pending += self._device.frames(FAST_READ_FRAMES)
        return len(self._pending)

    def read(self, size=1):
        if not self.is_open:
            raise PortNotOpenError()
        dev = self._device
        while len(self._pending) < size:
            if self._realtime:
                due = int((time.monotonic() - self._t0) * dev.rate_hz) - dev.sample_index
                if due <= 0:
                    if self._timeout is not None and len(self._pending) > 0:
                        break
                    time.sleep(min(0.005, 1.0 / dev.rate_hz * max(1, size // FRAME_LEN)))
                    continue
            else:
                due = max(1, (size - len(self._pending)) // FRAME_LEN + 1)
            self._pending += dev.frames(due)
        out, self._pending = self._pending[:size], self._pending[size:]
        return out

    def write(self, data):
        if not self.is_open:
            raise PortNotOpenError()
        return len(data)  # the firmware takes no commands

    def reset_input_buffer(self):
        self._pending = b""

    def reset_output_buffer(self):
        pass

    def _update_break_state(self):
        pass

    def _update_rts_state(self):
        pass

    def _update_dtr_state(self):
        pass

    @property
    def cts(self):
        return True

    @property
    def dsr(self):
        return True

    @property
    def ri(self):
        return False

    @property
    def cd(self):
        return True


def _calibrator(text: str | None) -> tuple[int, float, float] | None:
    """``CH[:HZ[:RMS]]`` -> (channel index, frequency, rms); defaults 159.2 Hz, 10 m/s^2."""
    if text is None:
        return None
    name, *rest = text.split(":")
    if name not in CHANNELS or len(rest) > 2:
        raise SerialException(f"rig:// option calibrator must be CHANNEL[:HZ[:RMS]] with CHANNEL one of "
                              f"{', '.join(CHANNELS)}, got {text!r}")
    try:
        hz = float(rest[0]) if rest else CALIBRATOR_HZ
        rms = float(rest[1]) if len(rest) > 1 else CALIBRATOR_RMS_M_PER_S2
    except ValueError:
        raise SerialException(f"rig:// option calibrator: {text!r} holds a value that is not a number") from None
    if not (0 < hz < 1e6 and 0 < rms < 1e6):
        raise SerialException(f"rig:// option calibrator: frequency and rms must be positive and finite, got {text!r}")
    return CHANNELS.index(name), hz, rms
