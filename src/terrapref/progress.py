"""Minimal progress reporting for long jobs (stderr; redrawn in place on a terminal)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable


class Progress:
    """Reports ``done / total`` with a label; quiet when ``enabled`` is False.

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
            sys.stderr.write(f"\r{self.label} [{bar:<30s}] {frac * 100:5.1f}% {note}   ")
            sys.stderr.flush()
        else:
            decile = int(frac * 10)
            if decile > self._last_decile:
                self._last_decile = decile
                sys.stderr.write(f"{self.label}: {frac * 100:3.0f}% {note}\n")

    def close(self, summary: str = "") -> None:
        if not self.enabled:
            return
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
