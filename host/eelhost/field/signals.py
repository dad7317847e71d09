"""Stop a run cleanly on Ctrl-C, on ``kill`` (SIGTERM) and when the terminal goes (SIGHUP).

While :func:`stop_on_signals` is active, each of those signals calls ``request_stop(name)`` (the
run loop then sends Stop and closes the recording at its next frame) instead of killing the
process; the previous handlers come back afterwards. SIGHUP does not exist on Windows and is
skipped there.
"""

from __future__ import annotations

import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["STOP_SIGNALS", "stop_on_signals"]

STOP_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)


@contextmanager
def stop_on_signals(request_stop: Callable[[str], None]) -> Iterator[list[str]]:
    """Turn SIGINT, SIGTERM and SIGHUP into ``request_stop(signal name)`` inside the block.

    Yields
    ------
    list of str
        The names of the signals received, in order.
    """
    received: list[str] = []

    def handler(signum: int, _frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        received.append(name)
        request_stop(name)

    previous = {s: signal.signal(s, handler) for s in STOP_SIGNALS}
    try:
        yield received
    finally:
        for s, old in previous.items():
            signal.signal(s, old)
