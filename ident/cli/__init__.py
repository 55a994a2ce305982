"""The command lines' shared plumbing: one-line errors, ``--version``, checked numbers, sample slices.

``ident.cli`` is the I/O edge of the science package: the ``ident`` command (``ident.cli.main``) and
its subcommands live here, and only here may ``ident`` compose other packages' readers. ``daq`` and
``replay`` use this module's helpers for their own commands:

- :class:`OneLineParser`: argparse that reports a usage error as one line, exit code 2, and gives every
  command and subcommand ``--version`` (from the installed package's metadata).
- :func:`run_guarded`: bad input (ValueError, OSError) is one line on stderr and exit code 2.
- :func:`number`: an argparse type for a finite number within a range (one line otherwise).
- :func:`parse_slice` and :func:`parse_split`: ``START:STOP`` sample slices; a training and a test slice
  that overlap are refused (held-out data must be held out).
"""

from __future__ import annotations

import argparse
import math
import os
import select
import sys
from collections.abc import Callable
from importlib.metadata import PackageNotFoundError, version

try:
    VERSION = version("shaker-ident")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without installing
    VERSION = "0+unknown"


class OneLineParser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exits 2; ``--version`` on every (sub)command."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.add_argument("--version", action="version", version=f"{self.prog} (shaker-ident) {VERSION}")

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog.split()[0]} --help)\n")


def run_guarded(prog: str, func: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run a command; bad input is one line on stderr and exit code 2, never a traceback."""
    try:
        code = func(args)
        sys.stdout.flush()  # (a pipe's reader gone is found here, not in the interpreter's exit)
        return code
    except BrokenPipeError as exc:
        if not _stdout_gone():  # a pipe of another kind (a port, a child's): an error as any other
            return _refused(prog, exc)
        try:  # what reads the output went away (`replay info F | head -3`): no more to say
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # (so the exit's flush is quiet)
        except (OSError, ValueError, AttributeError):
            pass
        return 141  # (as a command killed by SIGPIPE: 128 + 13)
    except (ValueError, OSError) as exc:
        return _refused(prog, exc)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130


def _refused(prog: str, exc: BaseException) -> int:
    text = " ".join(str(exc).split()) or type(exc).__name__
    print(f"{prog}: error: {text}", file=sys.stderr)
    return 2


def _stdout_gone() -> bool:
    """Is standard output a pipe whose reader has closed it (poll says POLLERR on its write end)?"""
    try:
        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(ev & select.POLLERR for _, ev in poll.poll(0))
    except (OSError, ValueError, AttributeError):  # no descriptor (a test's StringIO), or no poll here
        return False


def number(lo: float | None = None, hi: float | None = None, *, gt: bool = False, integer: bool = False,
           unit: str = "") -> Callable[[str], float]:
    """argparse type: a finite number with ``lo <= x <= hi`` (``lo < x`` with ``gt``), an integer with ``integer``."""

    def parse(text: str):
        try:
            value = int(text, 10) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if integer else 'a number'}") from None
        if not integer and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text} is not a finite number")
        u = f" {unit}" if unit else ""
        if lo is not None and (value <= lo if gt else value < lo):
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be {'>' if gt else '>='} {lo:g}{u}")
        if hi is not None and value > hi:
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be <= {hi:g}{u}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


# Ranges shared by the commands
DURATION = number(0.0, 1e7, gt=True, unit="s")  # finite, > 0, at most about 115 days
OFFSET = number(0.0, 1e7, unit="s")
RATE_HZ = number(1.0, 100_000.0, unit="Hz")
WINDOW = number(0.0, 600.0, gt=True, unit="s")
REGIME_WINDOW = number(0.25, 600.0, unit="s")  # the regime monitor's window: at least its hop (RegimeConfig.hop_s)
PLAY_RATE = number(0.01, 1000.0)
SEED = number(0, 2**32 - 1, integer=True)


def parse_slice(text: str | None, n: int, name: str, min_samples: int = 100) -> slice | None:
    """``START:STOP`` sample indices (Python-slice style, either may be empty, negatives count from the end)."""
    if text is None:
        return None
    parts = text.split(":")
    if len(parts) != 2:
        raise ValueError(f"--{name} must be START:STOP (sample indices, either may be empty), got {text!r}")
    try:
        start = int(parts[0]) if parts[0] else 0
        stop = int(parts[1]) if parts[1] else n
    except ValueError:
        raise ValueError(f"--{name} must hold integers, got {text!r}") from None
    s = slice(*slice(start, stop).indices(n)[:2])
    if s.stop - s.start < min_samples:
        raise ValueError(f"--{name} {text} selects {max(0, s.stop - s.start)} samples; give at least {min_samples}")
    return s


def parse_split(train: str | None, test: str | None, n: int, min_samples: int = 100) -> tuple[slice | None, slice | None]:
    """``--train`` and ``--test`` slices of ``n`` samples; refused if they share a sample."""
    a = parse_slice(train, n, "train", min_samples)
    b = parse_slice(test, n, "test", min_samples)
    if a is not None and b is not None and max(a.start, b.start) < min(a.stop, b.stop):
        raise ValueError(f"--train {train} and --test {test} overlap in samples {max(a.start, b.start)} to "
                         f"{min(a.stop, b.stop) - 1}: held-out data must not be trained on")
    return a, b
