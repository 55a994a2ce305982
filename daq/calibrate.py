"""``daq calibrate``: a channel's sensitivity from a handheld reference calibrator, written into the config.

The sensor sits on the calibrator (10 m/s^2 rms at 159.2 Hz by default) while the channel is recorded
through the same driver as ``daq record``; the 159.2 Hz line is fitted (daq.calibration) and its rms over
the calibrator's is the channel's sensitivity in counts per m/s^2. Without ``--port`` the simulated rig
serves, with a simulated calibrator on the channel (its sensor's gain, offset, noise and ADC apply).

Order (README "What is safe"): arguments, outputs checked against the inputs, config read, port opened;
the config is written only after a fit that passes its checks, as a new file (``-o``) or over
``--config`` with ``--force``, atomically (daq.safeio): a refused or interrupted calibration leaves every
file as it was. The file is rewritten from its parsed YAML: comments are not kept.
"""

from __future__ import annotations

import signal
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import yaml

from ident.cli import DURATION, number

from .calibration import CALIBRATOR_HZ, CALIBRATOR_RMS_M_PER_S2, calibrated_mapping, check_line, fit_sine, sensitivity
from .config import load_config, parse_config, read_yaml_file
from .driver import Acquisition
from .recorder import McapRecorder
from .safeio import Output, check_outputs, part_path, safe_output, same_file
from .sim.sensors import CHANNELS
from .transport import PtyServer


def add_parser(sub, add_link_options) -> None:
    c = sub.add_parser("calibrate", help="a channel's sensitivity from a handheld reference calibrator (10 m/s^2 "
                                         "rms at 159.2 Hz), written into the config")
    src = c.add_mutually_exclusive_group()
    src.add_argument("--port", help="serial device path or pyserial URL, as for daq record")
    src.add_argument("--sim", action="store_true", help="the simulated rig with a simulated calibrator on the "
                                                        "channel (the default)")
    c.add_argument("--channel", required=True, choices=CHANNELS, help="the channel whose sensor is on the calibrator")
    c.add_argument("--config", type=Path, help="the config to start from (YAML)")
    c.add_argument("-o", "--output", type=Path, help="the config to write (a new file); without it, --config is "
                                                     "updated in place, which needs --force")
    c.add_argument("--duration", type=DURATION, default=10.0, help="seconds to record (default 10)")
    c.add_argument("--reference-rms", type=number(0.0, 1e4, gt=True, unit="m/s^2"), default=CALIBRATOR_RMS_M_PER_S2,
                   help=f"the calibrator's level, m/s^2 rms (default {CALIBRATOR_RMS_M_PER_S2:g})")
    c.add_argument("--reference-hz", type=number(1.0, 50_000.0, unit="Hz"), default=CALIBRATOR_HZ,
                   help=f"the calibrator's nominal frequency (default {CALIBRATOR_HZ:g}; the fit finds the exact one "
                        "within 5 %%)")
    c.add_argument("--set-offset", action="store_true",
                   help="also write the offset that makes the channel's mean zero (AC-coupled sensors; a DC "
                        "sensor's mean holds gravity, keep its offset)")
    c.add_argument("--sensor-model", help="write the sensor's model, e.g. 'PCB 352C33'")
    c.add_argument("--serial-number", help="write the sensor's serial number")
    c.add_argument("--recording", type=Path, help="also keep the calibration run as an MCAP recording")
    c.add_argument("--force", action="store_true", help="update --config in place, replace an existing -o or "
                                                        "--recording")
    add_link_options(c)
    c.set_defaults(func=run)


def _port_file(port: str | None) -> Path | None:
    return Path(port) if port and "://" not in port else None


def run(args) -> int:
    if args.output is None and args.config is None:
        raise ValueError("give -o NEW.yaml (a new config), or --config FILE --force to update that file")
    out = args.output or args.config
    in_place = args.config is not None and same_file(out, args.config)
    if in_place and not args.force:
        raise ValueError(f"{out} is the config read: give --force to update it in place (atomically), or -o NEW.yaml")
    port_file = _port_file(args.port)
    inputs = [port_file] + ([] if in_place else [args.config])
    outputs = [Output("-o", out)]
    if args.recording is not None:
        outputs += [Output("--recording", args.recording),
                    Output("--recording", part_path(args.recording), replaceable=False)]
        check_outputs(outputs[1:], [args.config, port_file], args.force)
    check_outputs(outputs, inputs, args.force)
    cfg = load_config(args.config).with_link(args.format, args.baud)
    data = (read_yaml_file(args.config) if args.config else None) or {}
    ch = CHANNELS.index(args.channel)
    counts, clipped, seq = [], [], []

    def on_block(b):
        counts.append(np.asarray(b.counts[:, ch], np.float64))
        clipped.append(np.asarray(b.clipped, bool))
        seq.append(np.asarray(b.seq, np.int64))

    tmp = server = thread = None
    go = threading.Event()
    if args.port:
        port = args.port
    else:
        tmp = tempfile.TemporaryDirectory(prefix="daq-cal-")
        server = PtyServer(cfg, Path(tmp.name) / "rig", calibrator=(ch, args.reference_hz, args.reference_rms))
        port = str(server.link)
        thread = threading.Thread(target=server.serve, args=(args.duration + 1.0, go), daemon=True)
        thread.start()
    acq = Acquisition(port, cfg, on_block=on_block)
    rec = None
    try:
        acq.open()
        if args.recording is not None:
            rec = McapRecorder(args.recording, cfg, port=port, force=args.force, inputs=[args.config, port_file])
            acq.on_raw, acq.on_event, acq.on_status = rec.write_raw, rec.write_event, rec.write_device
            acq.on_block = lambda b: (on_block(b), rec.write_block(b))
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda signum, frame: acq.stop())
        print(f"recording {args.channel} on {args.port or 'the simulated rig'} for {args.duration:g} s: hold the "
              f"calibrator on the sensor ({args.reference_rms:g} m/s^2 rms at {args.reference_hz:g} Hz)", flush=True)
        acq.run(args.duration, opened=go)
    finally:
        if rec is not None:
            rec.write_status(acq.status())
            rec.close()
        if server is not None:
            server.stop()
            thread.join(timeout=5)
        if tmp is not None:
            tmp.cleanup()
    if acq.error:
        raise ValueError(f"calibration stopped: {acq.error}; the config was not written")
    if not counts:
        raise ValueError(f"no samples from {port} in {args.duration:g} s; the config was not written")
    x, clip, s = np.concatenate(counts), np.concatenate(clipped), np.concatenate(seq)
    if clip.any():
        raise ValueError(f"{int(clip.sum())} of {clip.size} samples clipped: the calibrator's level is beyond the "
                         f"channel's range (check the conditioner's gain); the config was not written")
    breaks = np.flatnonzero(np.diff(s) != 1) + 1  # the fit needs evenly spaced samples: the longest whole run
    edges = np.r_[0, breaks, s.size]
    k = int(np.argmax(np.diff(edges)))
    x = x[edges[k]:edges[k + 1]]
    try:
        fit = fit_sine(x, cfg.daq.rate_hz, args.reference_hz)
        check_line(fit)
    except ValueError as exc:
        raise ValueError(f"{args.channel}: {exc}; the config was not written") from None
    sens = sensitivity(fit, args.reference_rms)
    offset = -fit.offset / sens if args.set_offset else None
    before = cfg.scales()[0][ch]
    note = (f"{time.strftime('%Y-%m-%d %H:%M:%S')} daq calibrate: {args.reference_rms:g} m/s^2 rms at "
            f"{fit.frequency_hz:.3f} Hz (nominal {args.reference_hz:g}), {fit.n} samples, line {fit.snr_db:.1f} dB "
            f"above the rest")
    new = calibrated_mapping(data, args.channel, sens, note, offset, args.sensor_model, args.serial_number)
    parse_config(new, str(out))  # what is written must load
    text = (f"# written by daq calibrate ({args.channel}) from {args.config or 'the defaults'}; comments of the "
            f"original are not kept\n" + yaml.safe_dump(new, sort_keys=False))
    with safe_output(out, inputs=inputs, force=args.force, label="-o") as tmp_file:
        tmp_file.write_text(text)
    mean = fit.offset / sens
    print(f"{args.channel}: {sens:.6g} counts per m/s^2, i.e. {1.0 / sens:.6g} m/s^2 per count (was {before:.6g}, "
          f"{100 * ((1.0 / sens) / before - 1.0):+.2f} %), from {fit.rms:.6g} counts rms at {fit.frequency_hz:.3f} Hz "
          f"over {fit.n} samples (+-{100 * fit.amplitude_std / fit.amplitude:.2f} %, the line {fit.snr_db:.1f} dB "
          f"above the rest); mean {mean:+.4g} m/s^2 (offset {-mean:+.4g} "
          + ("written" if args.set_offset else "not written: --set-offset") + f"); config written to {out}")
    return 0
