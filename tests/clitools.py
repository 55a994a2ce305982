"""Run a command's ``main`` in this process, as a user would see it: exit code, stdout, stderr, and the
exception that would have been a traceback (None if there was none)."""

import io
import signal
from contextlib import redirect_stderr, redirect_stdout


def run_main(main, argv):
    """(exit code, stdout, stderr, traceback text or None); signal handlers the command sets are undone."""
    out, err = io.StringIO(), io.StringIO()
    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    tb = None
    try:
        with redirect_stdout(out), redirect_stderr(err):
            try:
                code = main([str(a) for a in argv])
            except SystemExit as exc:
                code = exc.code
    except Exception as exc:  # noqa: BLE001 - what the tests count: an exception a user would see as a traceback
        code, tb = -1, f"{type(exc).__name__}: {exc}"
    finally:
        for s, h in handlers.items():
            signal.signal(s, h)
    return code, out.getvalue(), err.getvalue(), tb
