"""What a real rig flashes: the reference firmware (Teensy 4.0 / 4.1, Arduino framework) and its frame encoder.

``rig_firmware/`` is an Arduino sketch folder: ``rig_firmware.ino`` (timer-driven sampling of three
analog channels, USB serial) and ``rigframe.c`` / ``rigframe.h``, the frame encoder in plain C99 that the
test suite compiles with the host's C compiler and checks against :mod:`daq.protocol`. Wiring, anti-alias
filtering and flashing: ``README.md`` beside this file. Nothing here runs on the host; the paths are for
the tests and for ``python -c "import daq.firmware as f; print(f.SKETCH_DIR)"`` (where pip put the sketch).
"""

from pathlib import Path

FIRMWARE_DIR = Path(__file__).resolve().parent
SKETCH_DIR = FIRMWARE_DIR / "rig_firmware"
SKETCH = SKETCH_DIR / "rig_firmware.ino"
ENCODER_C = SKETCH_DIR / "rigframe.c"
ENCODER_H = SKETCH_DIR / "rigframe.h"
