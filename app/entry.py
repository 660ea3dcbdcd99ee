"""The console entry point (``lbwater``; ``python -m app.cli`` goes the same way).

Importing this module makes Ctrl-C print one line, ``lbwater: interrupted``, and exit with status
130 at once: its first statements install that SIGINT handler, before anything heavy (argparse,
numpy, pyopencl) is imported, so an interrupt during the imports prints no traceback. Once
:func:`app.cli.main` is running it takes over (a KeyboardInterrupt it turns into the same line,
after a capture has closed its partial video); when it has returned, a Ctrl-C during the
interpreter's shut-down (Ray, OpenCL) exits at once, silently if the line was already printed.
"""

import os
import signal
import sys


def _interrupted(signum, frame, say: bool = True) -> None:
    if say:
        os.write(2, b"lbwater: interrupted\n")
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:   # a stream half-written when the signal came
            pass
    os._exit(130)


def install() -> None:
    """Ctrl-C: one line and status 130, now (before any import of ours)."""
    signal.signal(signal.SIGINT, _interrupted)


def installed() -> bool:
    return signal.getsignal(signal.SIGINT) is _interrupted


install()


def finish(status: int) -> int:
    """After :func:`app.cli.main` returned ``status``: a Ctrl-C during the shut-down exits at
    once (silently when main already said it was interrupted)."""
    signal.signal(signal.SIGINT, lambda s, f: _interrupted(s, f, say=status != 130))
    return status


def main(argv: list[str] | None = None) -> int:
    """``lbwater``: :func:`app.cli.main`, with Ctrl-C one line from the first statement on."""
    from app.cli import main as cli_main  # argparse and the rest: under the handler above

    return finish(cli_main(argv))
