"""Minimal progress reporting for long jobs (stderr; redrawn in place on a terminal)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable


def duration_text(seconds: float) -> str:
    """``42 s``, ``3 min 5 s`` or ``1 h 12 min``."""
    seconds = max(0, round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60} min"


def time_left(elapsed_s: float, frac: float) -> str:
    """``12 s, about 30 s left``: the time so far and, from the rate so far, what remains
    (none before a twentieth is done or a second has passed, too early to tell, nor in the last second)."""
    spent, left = duration_text(elapsed_s), elapsed_s * (1 - frac) / max(frac, 1e-9)
    if frac >= 1.0 or frac < 0.05 or elapsed_s < 1.0 or left < 1.0:
        return spent
    return f"{spent}, about {duration_text(left)} left"


class Progress:
    """Reports ``done / total`` with a label, the time so far and an estimate of the time left;
    quiet when ``enabled`` is False.

    On a terminal the line is redrawn in place; otherwise a line is printed every 10%.
    """

    def __init__(self, label: str, total: float, unit: str = "", enabled: bool = True) -> None:
        self.label, self.total, self.unit, self.enabled = label, max(total, 1e-9), unit, enabled
        self.tty = sys.stderr.isatty()
        self.start = time.perf_counter()
        self._last_decile = -1
        self._last_draw = 0.0

    def update(self, done: float, note: str = "") -> None:
        if not self.enabled:
            return
        frac = min(max(done / self.total, 0.0), 1.0)
        now = time.perf_counter()
        if self.tty:
            if now - self._last_draw < 0.1 and frac < 1.0:
                return
            self._last_draw = now
            bar = "#" * int(frac * 30)
            sys.stderr.write(f"\r{self.label} [{bar:<30s}] {frac * 100:5.1f}% {note} ({time_left(now - self.start, frac)})   ")
            sys.stderr.flush()
        else:
            decile = int(frac * 10)
            if decile > self._last_decile:
                self._last_decile = decile
                sys.stderr.write(f"{self.label}: {frac * 100:3.0f}% {note + ' ' if note else ''}({time_left(now - self.start, frac)})\n")

    def close(self, summary: str = "") -> None:
        """End the bar (once: later calls, and updates, do nothing), with ``summary`` if given."""
        if not self.enabled:
            return
        self.enabled = False
        if self.tty:
            sys.stderr.write("\n")
        if summary:
            sys.stderr.write(f"{self.label}: {summary} ({time.perf_counter() - self.start:.1f} s)\n")
        sys.stderr.flush()


def every_tenth(log: Callable[[str], None], what: str = "runs") -> Callable[[int, int], None]:
    """A ``(done, total)`` callback that logs ``done/total what`` each time another tenth is done."""
    reached = [0]

    def tick(done: int, total: int) -> None:
        if done * 10 // total > reached[0]:
            reached[0] = done * 10 // total
            log(f"      {done}/{total} {what}")

    return tick
