"""Ctrl-C that a compiled extension cannot swallow.

Python raises ``KeyboardInterrupt`` at the next bytecode the main thread runs after
SIGINT. When that bytecode belongs to a Python function that C code calls through
ctypes (numba's object-cache hooks, which LLVM calls while it loads or compiles a
kernel), ctypes reports the exception as unraisable and clears it, and the command
would run on to the end. :func:`catching_ctrl_c` re-delivers such an interrupt once
the main thread is back in ordinary Python code, so that it reaches
:func:`jamflow.cli.main` like any other Ctrl-C.
"""

from __future__ import annotations

import _thread
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

#: Seconds from a swallowed ``KeyboardInterrupt`` to its re-delivery: long against the
#: microseconds the swallowing callback needs to return into C, short against a keypress.
REDELIVERY_DELAY = 0.05

_reporting = False
_pending: list[threading.Timer] = []


@contextmanager
def catching_ctrl_c() -> Iterator[None]:
    """Within the block, a ``KeyboardInterrupt`` swallowed by an extension's callback is
    raised again; outside it the previous handlers hold.

    Only a process whose Ctrl-C raises ``KeyboardInterrupt`` is changed: one that ignores
    SIGINT (started in the background without job control, or under ``nohup``) keeps
    ignoring it.
    """
    previous_signal = signal.getsignal(signal.SIGINT)
    previous_hook = sys.unraisablehook
    take_signal = (previous_signal is signal.default_int_handler
                   and threading.current_thread() is threading.main_thread())
    if not take_signal:
        yield
        return

    def unraisable(report: sys.UnraisableHookArgs) -> None:
        global _reporting
        if report.exc_type is None or not issubclass(report.exc_type, KeyboardInterrupt):
            previous_hook(report)
            return
        _reporting = True
        try:
            _redeliver()
        finally:
            _reporting = False

    signal.signal(signal.SIGINT, _on_ctrl_c)
    sys.unraisablehook = unraisable
    try:
        yield
    finally:
        for timer in _pending:
            timer.cancel()
        _pending.clear()
        sys.unraisablehook = previous_hook
        signal.signal(signal.SIGINT, previous_signal)


def _on_ctrl_c(signum: int, frame: FrameType | None) -> None:
    if _reporting:
        # raised here it would be swallowed again, as an error of the unraisable hook
        _redeliver()
        return
    raise KeyboardInterrupt


def _redeliver() -> None:
    timer = threading.Timer(REDELIVERY_DELAY, _thread.interrupt_main, args=(signal.SIGINT,))
    timer.daemon = True
    _pending.append(timer)
    timer.start()
