"""Job progress: frames done, frames/s and ETA.

On a terminal a tqdm bar (it redraws one line in place, sizes itself to the terminal and
smooths the rate: not worth rewriting); otherwise (a log file, a Ray job's output) an INFO
log line at most every ``interval`` seconds and at the end.
"""

from __future__ import annotations

import logging
import sys
import time
from typing import Any

log = logging.getLogger("vhgen.progress")


def format_eta(seconds: float) -> str:
    """``1h02m``, ``3m05s`` or ``12s``."""
    s = int(round(max(seconds, 0.0)))
    if s >= 3600:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    if s >= 60:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s}s"


class Progress:
    """Counts frames; ``enabled=False`` shows nothing (``--quiet``)."""

    def __init__(self, total: int, *, enabled: bool = True, interval: float = 10.0,
                 stream: Any = None, tty: bool | None = None):
        self.total = int(total)
        self.done = 0
        self.enabled = enabled
        self.interval = interval
        self.t0 = time.perf_counter()
        self._last = self.t0
        stream = stream if stream is not None else sys.stderr
        tty = stream.isatty() if tty is None else tty
        self._bar = None
        if enabled and tty:
            from tqdm import tqdm

            self._bar = tqdm(total=self.total, unit="frame", file=stream, dynamic_ncols=True,
                             smoothing=0.1, desc="frames")

    def line(self) -> str:
        """``frames 40/240 (17%), 12.5 frames/s, ETA 16s``."""
        dt = time.perf_counter() - self.t0
        rate = self.done / dt if dt > 0 else 0.0
        eta = format_eta((self.total - self.done) / rate) if rate > 0 else "?"
        pct = 100.0 * self.done / self.total if self.total else 100.0
        return (f"frames {self.done}/{self.total} ({pct:.0f}%), {rate:.1f} frames/s, "
                f"ETA {eta}")

    def update(self, n: int) -> None:
        self.done += n
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(n)
            return
        now = time.perf_counter()
        if now - self._last >= self.interval or self.done >= self.total:
            self._last = now
            log.info("%s", self.line())

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
