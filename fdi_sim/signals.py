"""A stop request that arrived before a run installed its own handler (no imports: a signal handler sets it).

``fdi-sim``'s SIGINT and SIGTERM handler raises KeyboardInterrupt, but an exception raised while Python runs a
weakref callback (importlib's module-lock callbacks during an import) is unraisable: printed as
"Exception ignored" and dropped, and the command went on. Measured: 1 of 60 runs signalled
0.05-1.8 s after the start (the other core loaded) flew its 3000 s scenario to the end and exited
0; the same for SIGINT (the fresh-clone suite of session 10: a Ctrl-C test's child exited 0).
The handler therefore records the request here first; :class:`fdi_sim.sim.run.StopRequest`
reads it when it installs its own handler, so such a run stops before take-off.
"""
from __future__ import annotations

import signal

#: the reason a run and a command give for each stop signal
REASONS = {signal.SIGINT: "stopped by the user (Ctrl-C, SIGINT)", signal.SIGTERM: "stopped by SIGTERM"}

#: why the process was asked to stop ("" when it was not)
pending_reason: str = ""


def request(reason: str) -> None:
    """Record a stop request (called from a signal handler)."""
    global pending_reason
    pending_reason = pending_reason or reason


def stop_requested() -> bool:
    """Whether a stop was requested (for loops that must not rely on the exception arriving)."""
    return bool(pending_reason)


def clear() -> None:
    """Forget an earlier request (at the start of a command)."""
    global pending_reason
    pending_reason = ""
