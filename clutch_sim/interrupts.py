"""Ctrl-C at the CLI boundary: recognise an interrupt however it surfaces, and end quietly.

A SIGINT raises KeyboardInterrupt in the main thread, but it can surface wrapped: a numba
compiled function interrupted mid-call returns "SystemError: ... returned a result with an
exception set" whose context is the KeyboardInterrupt; Dask and concurrent.futures re-raise it
inside their own exceptions; rclpy shuts its context down and raises ExternalShutdownException
or RCLError. ``is_interrupt`` follows the exception chain; ``quiet`` makes sure nothing after
the one-line message prints a traceback (a second Ctrl-C, worker threads, interpreter exit).
"""
from __future__ import annotations

import signal
import sys
import threading

_interrupted = False


def _on_sigint(signum, frame):
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


def install() -> None:
    """Remember that SIGINT arrived (so wrapped errors after it count as the interrupt)."""
    if threading.current_thread() is threading.main_thread():
        try:
            if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                signal.signal(signal.SIGINT, _on_sigint)
        except (ValueError, OSError):
            pass


def is_interrupt(exc: BaseException) -> bool:
    """True when ``exc`` is, wraps or follows a Ctrl-C."""
    seen = set()
    e = exc
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    if _interrupted and isinstance(exc, (SystemError, RuntimeError)):
        return True
    return type(exc).__name__ == "ExternalShutdownException"


def quiet() -> None:
    """After the interrupt message: ignore further Ctrl-C and silence late tracebacks."""
    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except (ValueError, OSError):
        pass
    sys.excepthook = lambda *args: None
    threading.excepthook = lambda args: None
    sys.unraisablehook = lambda unraisable: None
