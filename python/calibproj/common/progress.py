"""Progress of long work: tqdm bars on a terminal, periodic log lines elsewhere.

On a terminal each task gets a tqdm bar; the command line routes log records through
``tqdm.write`` while bars are open (``logging_redirect_tqdm`` in ``calibproj.cli.main``),
so that a log line never cuts a bar. Without a terminal (a log file, CI, a pipe) bars
would only write carriage returns into the log, so each task logs one line instead
every ``interval_s`` seconds and one when it ends.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from typing import Any

logger = logging.getLogger(__name__)

DEFAULT_INTERVAL_S = 10.0


def progress_bar(total: int | None, description: str, enabled: bool = True, position: int | None = None,
                 unit: str = "frame", interval_s: float = DEFAULT_INTERVAL_S, stream: Any = None) -> Any:
    """A tqdm bar when ``stream`` (default: stderr) is a terminal, else a
    :class:`PeriodicProgress`; both have ``update``, ``n``, ``total`` and ``close``.
    With ``enabled`` false, a bar that shows nothing."""
    from tqdm import tqdm

    stream = sys.stderr if stream is None else stream
    if not enabled:
        return tqdm(total=total, disable=True)
    if _is_terminal(stream):
        # smoothing=0: the rate shown is the task's own average, also once it is closed.
        return tqdm(total=total, desc=description, unit=unit, position=position, leave=True, file=stream,
                    smoothing=0)
    return PeriodicProgress(total, description, unit, interval_s)


def _is_terminal(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


class PeriodicProgress:
    """A task's progress as a log line every ``interval_s`` seconds and one at the end.
    Thread-safe (the ingest updates it from its C++ threads)."""

    def __init__(self, total: int | None, description: str, unit: str = "frame",
                 interval_s: float = DEFAULT_INTERVAL_S) -> None:
        self.total = total
        self.n = 0
        self.description = description
        self.unit = unit
        self.interval_s = interval_s
        self.started = time.monotonic()
        self.last_line = self.started
        self.closed = False
        self.lock = threading.Lock()

    def update(self, count: int = 1) -> None:
        with self.lock:
            self.n += count
            now = time.monotonic()
            if self.total and self.n >= self.total and not self.closed:
                self.closed = True  # done now, not when the caller gets round to closing
                self._log(now, final=True)
            elif now - self.last_line >= self.interval_s and not self.closed:
                self.last_line = now
                self._log(now)

    def close(self) -> None:
        with self.lock:
            if not self.closed:
                self.closed = True
                self._log(time.monotonic(), final=True)

    def _log(self, now: float, final: bool = False) -> None:
        elapsed = now - self.started
        rate = self.n / elapsed if elapsed > 0 else 0.0
        share = f" ({100.0 * self.n / self.total:.0f} %)" if self.total else ""
        of = f"/{self.total}" if self.total else ""
        state = "done" if final else "working"
        logger.info("%s: %s, %d%s %ss%s in %.0f s (%.0f %s/s)", self.description, state, self.n, of, self.unit,
                    share, elapsed, rate, self.unit)
