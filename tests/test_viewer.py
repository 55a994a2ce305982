"""The live viewer listens on this machine only: every listening socket of the command (and of the rerun
server it starts) is on 127.0.0.1, none on 0.0.0.0 or ::, read from /proc/net/tcp{,6}; the URL printed
opens the live recording (the web viewer answers, the data server accepts connections)."""

import os
import re
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from urllib.parse import unquote

import pytest

REC = Path(__file__).resolve().parents[1] / "recordings"


def _children(pid: int) -> list[int]:
    out = [pid]
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids = (task / "children").read_text().split()
        except OSError:
            continue
        for k in kids:
            out += _children(int(k))
    return out


def _socket_inodes(pids: list[int]) -> set[str]:
    inodes = set()
    for pid in pids:
        for fd in Path(f"/proc/{pid}/fd").glob("*"):
            try:
                target = os.readlink(fd)
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
    return inodes


def _listening(inodes: set[str]) -> list[tuple[str, int]]:
    """(address, port) of every LISTEN socket among ``inodes`` (state 0A in /proc/net/tcp and tcp6)."""
    found = []
    for table, v6 in (("/proc/net/tcp", False), ("/proc/net/tcp6", True)):
        for line in Path(table).read_text().splitlines()[1:]:
            f = line.split()
            if f[3] != "0A" or f[9] not in inodes:
                continue
            addr, port = f[1].split(":")
            raw = bytes.fromhex(addr)
            if v6:
                ip = socket.inet_ntop(socket.AF_INET6, b"".join(raw[i:i + 4][::-1] for i in range(0, 16, 4)))
            else:
                ip = socket.inet_ntop(socket.AF_INET, raw[::-1])
            found.append((ip, int(port, 16)))
    return found


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="needs Linux /proc")
def test_web_viewer_and_data_server_listen_on_localhost_only():
    proc = subprocess.Popen([sys.executable, "-m", "replay", str(REC / "linear.mcap"), "--viewer", "web",
                             "--no-identify", "--duration", "6"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        line = proc.stderr.readline()
        m = re.match(r"web viewer: (http://127\.0\.0\.1:(\d+)/\?url=(\S+)) \(listening on 127\.0\.0\.1 only", line)
        assert m, line
        web, data = int(m.group(2)), unquote(m.group(3))
        assert re.fullmatch(r"rerun\+http://127\.0\.0\.1:\d+/proxy", data), data
        grpc = int(data.split(":")[-1].split("/")[0])
        time.sleep(0.5)
        listening = _listening(_socket_inodes(_children(proc.pid)))
        assert {(a, p) for a, p in listening} >= {("127.0.0.1", web), ("127.0.0.1", grpc)}, listening
        assert all(a == "127.0.0.1" for a, _ in listening), listening  # nothing on 0.0.0.0 or ::
        with urllib.request.urlopen(m.group(1), timeout=10) as r:  # the printed URL serves the viewer
            assert r.status == 200 and b"<html" in r.read(2000).lower()
        with socket.create_connection(("127.0.0.1", grpc), timeout=5):
            pass
        print(f"\nlistening: {sorted(set(listening))}")
    finally:
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "played 6.00 s" in out
    for port in (web, grpc):  # the servers end with the command: nothing keeps listening
        with pytest.raises(OSError):
            socket.create_connection(("127.0.0.1", port), timeout=2).close()
