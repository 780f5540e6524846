"""A dependency-free progress bar for long stages, drawn on one rank only (pass ``enabled``)."""
from __future__ import annotations

import sys
import time


class ProgressBar:
    """``with ProgressBar(n, "transient") as bar: bar.update(i)``.  On a terminal the bar is
    redrawn in place; otherwise (logs, CI) a line is printed every 10 % and, with ``heartbeat``,
    at least every ``heartbeat`` seconds of updates (a stage that moves slowly still shows its state)."""

    def __init__(self, total: float, label: str, *, enabled: bool = True, stream=None, unit: str = "",
                 heartbeat: float | None = None):
        self.total, self.label, self.enabled, self.unit = float(total), label, enabled, unit
        self.heartbeat = heartbeat
        self._last_line = time.perf_counter()
        self.stream = stream or sys.stderr
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.t0 = time.perf_counter()
        self._last_draw = 0.0
        self._last_decile = -1

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc) -> None:
        if self.enabled and exc[0] is None:
            self.close()

    def close(self) -> None:
        """Draw the bar full (the work is done) and end its line."""
        if not self.enabled:
            return
        self.update(self.total, force=True)
        self.abandon()

    def abandon(self) -> None:
        """End the bar's line on a terminal without drawing it full (the work stopped short)."""
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()

    def note(self, text: str) -> None:
        """A line of its own after the bar (``<label>: text``): what the bar cannot show."""
        if self.enabled:
            self.stream.write(("\n" if self.tty else "") + f"{self.label}: {text}\n")
            self.stream.flush()

    def update(self, done: float, force: bool = False, extra: str = "", eta: float | None = None) -> None:
        """Draw ``done`` of the total; ``eta``: the caller's estimate of the seconds left (NaN: not
        known yet), else elapsed × (1 − share done)/share done."""
        if not self.enabled:
            return
        frac = min(max(done / self.total, 0.0), 1.0) if self.total > 0 else 1.0
        now = time.perf_counter()
        elapsed = now - self.t0
        if eta is None:
            eta = elapsed * (1 - frac) / frac if frac > 0 else float("nan")
        text = (f"{self.label}: {100 * frac:5.1f}% {done:.4g}/{self.total:.4g}{self.unit} "
                f"elapsed {elapsed:.1f} s, eta {'?' if eta != eta else f'{eta:.1f} s'} {extra}")
        if self.tty:
            if force or now - self._last_draw > 0.2:
                bar = "#" * int(30 * frac)
                self.stream.write(f"\r[{bar:<30}] {text}")
                self.stream.flush()
                self._last_draw = now
        else:
            decile = int(10 * frac)
            beat = self.heartbeat is not None and now - self._last_line >= self.heartbeat
            if decile > self._last_decile or beat or (force and frac >= 1 and self._last_decile < 10):
                self._last_decile = max(decile, self._last_decile)
                self._last_line = now
                self.stream.write(text + "\n")
                self.stream.flush()
