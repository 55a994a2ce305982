"""Look at the live view as a person would: record a short run, open it in the web viewer in headless
Chromium, save a PNG.

    python -m daq.tools.screenshot_view [-o view.png] [--source sim|FILE.mcap] [--duration S] [--wait S]

``--source sim`` (default) records ``--duration`` seconds from the simulated rig with ``daq record
--viewer save``; a recording (``recordings/transitions.mcap``) is replayed at full speed instead. The
``.rrd`` is compacted (``rerun rrd optimize``) and served by the ``rerun`` executable on 127.0.0.1 (``--serve-web``), Chromium loads the
web viewer and is driven over its DevTools pipe (``--remote-debugging-pipe``: JSON messages separated
by NUL bytes on file descriptors 3 and 4, no network port, no extra package): wait ``--wait`` seconds of
real time for the viewer to load and draw, then ``Page.captureScreenshot``.
"""

from __future__ import annotations

import argparse
import base64
import fcntl
import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from urllib.parse import quote

from daq.safeio import Output, check_outputs, safe_output
from daq.viewer import _rerun_exe, _wait_listening, free_port

CHROMIUM = "/usr/bin/chromium"
WIDTH, HEIGHT = 1600, 1000


class DevToolsPipe:
    """Chromium's DevTools protocol over --remote-debugging-pipe (fd 3: commands in, fd 4: replies out)."""

    def __init__(self, args: list[str]):
        to_chrome_r, self._w = os.pipe()
        self._r, from_chrome_w = os.pipe()
        # above 4, so that the shell's redirections to 3 and 4 cannot overwrite one of them
        low = (to_chrome_r, from_chrome_w)
        to_chrome_r, from_chrome_w = (fcntl.fcntl(fd, fcntl.F_DUPFD, 10) for fd in low)
        for fd in low:
            os.close(fd)

        # the child sees the pipes as fds 3 and 4, set up by the shell's redirections
        shell = f'exec "$@" 3<&{to_chrome_r} 4>&{from_chrome_w} {to_chrome_r}<&- {from_chrome_w}>&-'
        self.proc = subprocess.Popen(["/bin/bash", "-c", shell, "chromium", *args, "--remote-debugging-pipe"],
                                     pass_fds=(to_chrome_r, from_chrome_w), stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, start_new_session=True)
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self._buf = b""
        self._id = 0

    def call(self, method: str, session: str | None = None, timeout_s: float = 60.0, **params) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            while b"\0" in self._buf:
                raw, self._buf = self._buf.split(b"\0", 1)
                reply = json.loads(raw)
                if reply.get("id") == self._id:
                    if "error" in reply:
                        raise RuntimeError(f"{method}: {reply['error']}")
                    return reply.get("result", {})
            ready, _, _ = select.select([self._r], [], [], max(0.0, end - time.monotonic()))
            if not ready:
                break
            chunk = os.read(self._r, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the DevTools pipe")
            self._buf += chunk
        raise TimeoutError(method)

    def close(self) -> None:
        try:
            os.killpg(self.proc.pid, signal.SIGTERM)
            self.proc.wait(timeout=10)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            pass
        os.close(self._w)
        os.close(self._r)


def record(source: str, duration_s: float, folder: Path) -> Path:
    """A short run with ``--viewer save``; returns the .rrd."""
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    if source == "sim":
        out = folder / "sim.mcap"
        cmd = [sys.executable, "-m", "daq", "record", "-o", str(out), "--duration", f"{duration_s:g}",
               "--viewer", "save"]
    else:
        out = folder / Path(source).name
        cmd = [sys.executable, "-m", "replay", source, "--max", "--viewer", "save", "--rrd",
               str(out.with_suffix(".rrd"))]
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        last = (p.stderr.strip().splitlines() or [f"exit {p.returncode}"])[-1]
        raise RuntimeError(f"recording the run failed: {last}")
    return out.with_suffix(".rrd")


def compact(rrd: Path, folder: Path) -> Path:
    """``rerun rrd optimize``: a live recording holds a chunk per block and entity (thousands), which the web
    viewer ingests slowly; compacted, the same data loads in seconds."""
    out = folder / f"{rrd.stem}-compact.rrd"
    p = subprocess.run([_rerun_exe(), "rrd", "optimize", str(rrd), "-o", str(out)], capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"rerun rrd optimize failed: {(p.stderr.strip().splitlines() or ['?'])[-1]}")
    return out


def screenshot(rrd: Path, png: Path, wait_s: float, *, force: bool = False, inputs: tuple = ()) -> None:
    bind = "127.0.0.1"
    grpc, web = free_port(bind, 19876), free_port(bind, 19090)
    server = subprocess.Popen([_rerun_exe(), "--serve-web", "--bind", bind, "--port", str(grpc),
                               "--web-viewer-port", str(web), str(rrd)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    chrome = None
    try:
        _wait_listening(bind, grpc, server)
        _wait_listening(bind, web, server)
        url = f"http://{bind}:{web}/?url={quote(f'rerun+http://{bind}:{grpc}/proxy', safe='')}"
        with tempfile.TemporaryDirectory(prefix="chromium-") as profile:
            chrome = DevToolsPipe([CHROMIUM, "--headless", "--no-sandbox", "--use-angle=swiftshader",
                                   "--enable-unsafe-swiftshader", "--hide-scrollbars", "--no-first-run",
                                   f"--user-data-dir={profile}", f"--window-size={WIDTH},{HEIGHT}", "about:blank"])
            target = chrome.call("Target.createTarget", url="about:blank")["targetId"]
            session = chrome.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
            chrome.call("Emulation.setDeviceMetricsOverride", session, width=WIDTH, height=HEIGHT,
                        deviceScaleFactor=1, mobile=False)
            chrome.call("Page.enable", session)
            chrome.call("Page.navigate", session, url=url)
            time.sleep(wait_s)  # the viewer's wasm bundle loads, the recording streams in, the plots draw
            data = chrome.call("Page.captureScreenshot", session, format="png")["data"]
            with safe_output(png, inputs=[rrd, *inputs], force=force, label="-o") as tmp:
                tmp.write_bytes(base64.b64decode(data))
            chrome.close()
            chrome = None
    finally:
        if chrome is not None:
            chrome.close()
        try:
            os.killpg(server.pid, signal.SIGTERM)
            server.wait(timeout=10)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            pass


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m daq.tools.screenshot_view", description=__doc__.splitlines()[0])
    p.add_argument("-o", "--output", type=Path, default=Path("view.png"))
    p.add_argument("--source", default="sim", help="sim (default: record the simulated rig) or an .mcap to replay")
    p.add_argument("--duration", type=float, default=20.0, help="seconds to record from the simulated rig")
    p.add_argument("--wait", type=float, default=40.0, help="seconds to let the web viewer load and draw")
    p.add_argument("--rrd", type=Path, help="screenshot this .rrd instead of recording one")
    p.add_argument("--force", action="store_true", help="replace an existing --output")
    args = p.parse_args(argv)
    inputs = (args.rrd, None if args.source == "sim" else Path(args.source))
    try:
        check_outputs([Output("-o", args.output)], inputs, args.force)  # before minutes of recording
        if not os.path.exists(CHROMIUM):
            raise RuntimeError(f"{CHROMIUM} not found (Debian package chromium)")
        with tempfile.TemporaryDirectory(prefix="screenshot-view-") as tmp:
            rrd = compact(args.rrd or record(args.source, args.duration, Path(tmp)), Path(tmp))
            screenshot(rrd, args.output, args.wait, force=args.force, inputs=inputs)
    except (RuntimeError, TimeoutError, ValueError, OSError) as exc:
        print(f"screenshot_view: {exc}", file=sys.stderr)
        return 2
    print(f"screenshot: {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
