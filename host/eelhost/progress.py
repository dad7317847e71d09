"""Progress of long commands, in the form that fits where it goes.

Every ``eelbot`` command that can take more than a few seconds reports its progress through
:class:`Progress`; the global option ``--progress`` (:func:`set_mode`) chooses the form:

- ``bar``: a tqdm bar on stderr, redrawn in place (for a terminal);
- ``plain``: a timestamped line on stderr every few seconds and one at the end, no escape codes
  (for a log file or a CI job); a task done within the first interval writes nothing;
- ``none``: nothing;
- ``auto`` (default): ``bar`` when stderr is a terminal, else ``plain``.

:func:`message` prints a line to stderr without gluing it to a bar being drawn (the command line
prints its error messages with it), :func:`console` does the same for everything a command prints
and logs while bars are drawn, and :func:`close_all` ends every bar still open (before an error
message, when a command fails half-way).

:func:`phase` is for a stage that has nothing to count as it goes (a cross-validation, a
bootstrap, a validation whose work happens inside a library call): it shows the stage's name and
the time it has taken, refreshed by a background thread (every second on a bar, a line every
5 s in plain form), so that no stage of a command is silent for more than a few seconds
(docs/cli.md, "Progress").
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import TracebackType
from typing import Any, TextIO

from tqdm import tqdm
from tqdm.contrib.logging import logging_redirect_tqdm

__all__ = [
    "MODES",
    "PLAIN_INTERVAL_S",
    "Progress",
    "close_all",
    "console",
    "message",
    "mode",
    "phase",
    "set_mode",
]

MODES = ("auto", "bar", "plain", "none")
PLAIN_INTERVAL_S = 5.0  # seconds between two plain lines: a log stays short and still shows life

_mode = "auto"
_open: set[Progress] = set()  # strong: a display dropped unclosed still ends at close_all


def set_mode(new_mode: str) -> None:
    """Choose how progress is shown: one of :data:`MODES`."""
    global _mode
    if new_mode not in MODES:
        raise ValueError(f"progress mode must be one of {', '.join(MODES)}, got {new_mode!r}")
    _mode = new_mode


def mode(stream: TextIO | None = None) -> str:
    """The form progress takes now: ``bar``, ``plain`` or ``none`` (``auto`` resolved)."""
    if _mode != "auto":
        return _mode
    stream = stream or sys.stderr
    isatty = getattr(stream, "isatty", None)
    return "bar" if isatty is not None and isatty() else "plain"


def close_all() -> None:
    """Close every progress display still open (a command failed while it was drawn)."""
    for p in list(_open):
        p.close()


def message(text: str) -> None:
    """Print a line to stderr, on a line of its own even while a bar is drawn."""
    if any(p._bar is not None for p in list(_open)):
        tqdm.write(text, file=sys.stderr)
    else:
        print(text, file=sys.stderr, flush=True)


def _bars() -> list[tqdm]:
    return [p._bar for p in list(_open) if p._bar is not None]


class _AboveBars:
    """A text stream that writes whole lines above the bars being drawn (bars redrawn after)."""

    def __init__(self, wrapped: TextIO) -> None:
        self._wrapped = wrapped
        self._partial = ""

    def write(self, text: str) -> int:
        head, newline, self._partial = (self._partial + text).rpartition("\n")
        if newline:
            bars = _bars()
            for bar in bars:
                bar.clear()
            self._wrapped.write(head + newline)
            self._wrapped.flush()
            for bar in bars:
                bar.refresh()
        return len(text)

    def flush(self) -> None:
        if self._partial:
            self._wrapped.write(self._partial)
            self._partial = ""
        self._wrapped.flush()

    def __getattr__(self, name: str) -> Any:  # isatty, fileno, encoding ... of the real stream
        return getattr(self._wrapped, name)


@contextmanager
def console() -> Iterator[None]:
    """While bars may be drawn, print and log above them instead of onto their line.

    In ``bar`` form, stdout is wrapped so that each whole line is written above the bars and
    log records go through tqdm; in the other forms nothing changes.
    """
    if mode() != "bar":
        yield
        return
    real = sys.stdout
    above = _AboveBars(real)
    sys.stdout = above  # type: ignore[assignment]
    try:
        with logging_redirect_tqdm():
            yield
    finally:
        above.flush()
        sys.stdout = real


class Progress:
    """The progress of one task: a count towards an optional total.

    Use it as a context manager (it closes on exit, also on an exception), or call :meth:`close`.

    Parameters
    ----------
    desc : str
        What is being done (``"fit straight (cmaes)"``).
    total : int, optional
        The count at which the task is done (None: unknown, only the count is shown).
    unit : str
        What is counted (``"step"``, ``"experiment"``, ``"gen"``).
    interval_s : float, optional
        In ``plain`` form, the seconds between two lines (default :data:`PLAIN_INTERVAL_S`).
    stream : file, optional
        Where it goes (default stderr, read when the progress starts).
    elapsed_only : bool
        Show the time taken instead of a count (:func:`phase`).
    """

    def __init__(
        self,
        desc: str,
        total: int | None = None,
        unit: str = "it",
        interval_s: float | None = None,
        stream: TextIO | None = None,
        elapsed_only: bool = False,
    ) -> None:
        self.desc = desc
        self.total = total
        self.unit = unit
        self.n = 0
        self.interval_s = PLAIN_INTERVAL_S if interval_s is None else interval_s
        self._stream = stream or sys.stderr
        self._form = mode(self._stream)
        self._postfix: dict[str, Any] = {}
        self._t0 = time.monotonic()
        self._last_line = self._t0
        self._closed = False
        self._failed = False
        self._bar: tqdm | None = None
        self._elapsed_only = elapsed_only
        if self._form == "bar":
            self._bar = tqdm(
                total=total, unit=unit, desc=desc, file=self._stream,
                bar_format="{desc}: {elapsed}{postfix}" if elapsed_only else None,
            )
        _open.add(self)

    def __enter__(self) -> Progress:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._failed = exc_type is not None
        self.close()

    def update(self, n: int = 1) -> None:
        """Count ``n`` more."""
        self.set(self.n + n)

    def set(self, done: int) -> None:
        """Set the count to ``done``."""
        self.n = done
        if self._bar is not None:
            self._bar.update(done - self._bar.n)
        elif self._form == "plain":
            now = time.monotonic()
            if now - self._last_line >= self.interval_s and done != self.total:  # close says it
                self._last_line = now
                self._line()

    def set_postfix(self, **values: Any) -> None:
        """Show these values after the count (``best=0.12, sims=600``)."""
        self._postfix = values
        if self._bar is not None:
            self._bar.set_postfix(values, refresh=False)

    def finish(self) -> None:
        """Mark the task done: the count jumps to the total (a run that stopped at its goal)."""
        if self.total is not None:
            self.set(self.total)

    def close(self) -> None:
        """End the display (a last line in ``plain`` form); idempotent."""
        if self._closed:
            return
        self._closed = True
        _open.discard(self)
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self._form == "plain" and (
            self._last_line > self._t0 or time.monotonic() - self._t0 >= self.interval_s
        ):  # a task done within one interval leaves no line: the log stays short
            self._line(final=True)

    def _line(self, final: bool = False) -> None:
        elapsed = time.monotonic() - self._t0
        if self._elapsed_only:
            state = ("stopped after" if self._failed else "done in") if final else "for"
            extra = "".join(f", {k} {v}" for k, v in self._postfix.items())
            self._stream.write(f"{time.strftime('%H:%M:%S')} {self.desc}: {state} "
                               f"{elapsed:.0f} s{extra}\n")
            self._stream.flush()
            return
        count = f"{self.n}/{self.total}" if self.total is not None else f"{self.n}"
        percent = f" ({100.0 * self.n / self.total:.0f} %)" if self.total else ""
        extra = "".join(f", {k} {v}" for k, v in self._postfix.items())
        state = ("stopped at" if self._failed else "done") if final else "at"
        self._stream.write(
            f"{time.strftime('%H:%M:%S')} {self.desc}: {state} {count} {self.unit}{percent}"
            f"{extra}, {elapsed:.0f} s\n"
        )
        self._stream.flush()


@contextmanager
def phase(desc: str, status: Callable[[], dict[str, Any]] | None = None,
          tick_s: float = 1.0) -> Iterator[Progress]:
    """Show a stage that has nothing to count as it goes: its name and the time it has taken.

    A background thread refreshes it every ``tick_s`` (a bar shows the time; the plain form
    writes a line every :data:`PLAIN_INTERVAL_S`, and one at the end if it lasted that long).

    Parameters
    ----------
    desc : str
        The stage (``"cross-validation of 6 candidate models"``).
    status : callable, optional
        Called at each refresh and once more for the closing line; its values are shown after
        the time (``sims=1200``).
    tick_s : float
        Seconds between refreshes.

    Yields
    ------
    Progress
        Its display (``set_postfix`` works on it too).
    """
    shown = Progress(desc, None, "s", elapsed_only=True)
    stop = threading.Event()

    def tick() -> None:
        while not stop.wait(tick_s):
            if status is not None:
                shown.set_postfix(**status())
            shown.set(int(time.monotonic() - shown._t0))

    thread = threading.Thread(target=tick, name=f"progress: {desc}", daemon=True)
    thread.start()
    try:
        yield shown
    except BaseException:
        shown._failed = True
        raise
    finally:
        stop.set()
        thread.join()  # no refresh after the last line
        if status is not None:
            # the closing line's values: the last work may have come back after the last tick
            # (the comparison's said 227 331 simulations of its table's 227 981)
            shown.set_postfix(**status())
        shown.close()
