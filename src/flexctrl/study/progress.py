"""A progress display for a running study, on stderr.

On a terminal: one line redrawn in place (a bar, runs done and failed, elapsed
time and the time left).  Elsewhere (a log file, CI): the same facts as plain
lines, at most one every ``interval`` seconds, plus a last line at the end.
``mode="none"`` prints nothing.  The time left is the mean time per finished
run of this session times the runs left (runs are spread over the workers,
so this already accounts for parallelism).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import TextIO

MODES = ("auto", "bar", "lines", "none")


def _clock_text(seconds: float) -> str:
    seconds = int(round(max(seconds, 0.0)))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


class Progress:
    """Counts finished runs and shows them.

    Parameters
    ----------
    total
        Runs to do in this session.
    skipped
        Runs already recorded (shown, not counted in ``total``).
    label
        Shown first on every line (the study's name).
    mode
        ``"auto"`` (bar on a terminal, lines otherwise), ``"bar"``, ``"lines"`` or ``"none"``.
    stream
        Where to write (default ``sys.stderr``).
    interval
        Seconds between plain lines.
    clock
        Monotonic clock (s); injectable for tests.
    """

    def __init__(
        self,
        total: int,
        *,
        skipped: int = 0,
        label: str = "",
        mode: str = "auto",
        stream: TextIO | None = None,
        interval: float = 5.0,
        clock: Callable[[], float] = time.monotonic,
    ):
        if mode not in MODES:
            raise ValueError(f"progress mode {mode!r} is not allowed; allowed: {', '.join(MODES)}")
        self.stream = stream if stream is not None else sys.stderr
        if mode == "auto":
            mode = "bar" if getattr(self.stream, "isatty", lambda: False)() else "lines"
        self.mode = mode
        self.total = total
        self.skipped = skipped
        self.label = label
        self.interval = interval
        self.clock = clock
        self.done = 0
        self.failed = 0
        self.start = clock()
        self._last_draw = -float("inf")
        self._last_line = ""
        self._closed = False
        if self.mode == "lines":
            self._emit(self.text())
            self._last_draw = self.start

    @property
    def elapsed(self) -> float:
        """Seconds since the start."""
        return self.clock() - self.start

    def time_left(self) -> float | None:
        """Estimated seconds left, or None before the first run finishes."""
        if self.done == 0:
            return None
        return self.elapsed / self.done * (self.total - self.done)

    def text(self) -> str:
        """The status as one line of text."""
        left = self.time_left()
        if self.total == 0:
            prefix = f"{self.label}: " if self.label else ""
            return prefix + f"nothing to run ({self.skipped} already recorded)"
        parts = [f"{self.done}/{self.total} runs done", f"{self.failed} failed"]
        if self.skipped:
            parts.append(f"{self.skipped} already recorded")
        parts.append(f"elapsed {_clock_text(self.elapsed)}")
        parts.append("left ?" if left is None else f"left ~{_clock_text(left)}")
        prefix = f"{self.label}: " if self.label else ""
        if self.mode == "bar":
            width = 24
            filled = int(width * self.done / self.total) if self.total else width
            prefix += "[" + "#" * filled + "." * (width - filled) + "] "
        return prefix + ", ".join(parts)

    def update(self, ok: bool) -> None:
        """Count one finished run (``ok`` False for a failed one)."""
        self.done += 1
        self.failed += 0 if ok else 1
        now = self.clock()
        if self.mode == "bar" and now - self._last_draw >= 0.1:
            self._emit("\r" + self.text() + "\x1b[K", newline=False)
            self._last_draw = now
        elif self.mode == "lines" and now - self._last_draw >= self.interval:
            self._emit(self.text())
            self._last_draw = now

    def close(self) -> None:
        """The last line."""
        if self._closed:
            return
        self._closed = True
        if self.mode == "bar":
            self._emit("\r" + self.text() + "\x1b[K")
        elif self.mode == "lines" and self.text() != self._last_line:
            self._emit(self.text())

    def _emit(self, text: str, newline: bool = True) -> None:
        if self.mode == "none":
            return
        if newline:
            self._last_line = text
        self.stream.write(text + ("\n" if newline else ""))
        self.stream.flush()
