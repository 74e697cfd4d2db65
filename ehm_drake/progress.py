"""Progress of long work on stderr, one helper for every long command
(simulations, fits, linearizations, syntheses, diagnoses, blind runs,
sweeps).

On a terminal a bar is redrawn in place (at most twice a second); in a log
(stderr not a terminal) a line is written when a step finishes or another
tenth of the total is done, so CI logs stay short.  The estimate of the
time left counts only the work done by this call (`start` items already
done, e.g. reused from an earlier run, take no time).  Nothing here catches
Ctrl-C: long work is done in chunks between which a KeyboardInterrupt
reaches the caller.
"""

from __future__ import annotations

import sys
import time


class Progress:
    """One task's progress: ``done`` of ``total`` units (None: unknown).

    Parameters
    ----------
    label : printed first on each line ("simulate", "sweep", ...).
    total : units of work (seconds of simulated time, runs, trials);
        None for a task whose size is not known in advance.
    enabled : False makes every method a no-op (``--quiet``).
    start : units already done before this call (not counted in the rate).
    unit : short unit name shown after the counts ("runs"; "" for none).
    stream : where to write (default sys.stderr, looked up at each write).
    """

    def __init__(self, label: str, total: float | None = None, enabled: bool = True,
                 start: float = 0.0, unit: str = "", stream=None):
        self.label, self.total, self.enabled = label, total, enabled
        self.start, self.unit = start, unit
        self._stream = stream
        self.t0 = time.perf_counter()
        self._rate_t0 = self.t0  # the rate counts the work since then
        self.done = start
        self._last_draw = -1.0
        self._open = False  # a bar line is on screen without its newline
        self._logged_tenth = -1  # last tenth of the total written to a log

    @property
    def stream(self):
        return self._stream if self._stream is not None else sys.stderr

    @property
    def elapsed(self) -> float:
        """Wall time since this call started, s."""
        return time.perf_counter() - self.t0

    def eta(self) -> float | None:
        """Seconds left at this call's rate (None before any progress or
        without a total)."""
        ran = self.done - self.start
        if self.total is None or ran <= 0:
            return None
        return (time.perf_counter() - self._rate_t0) / ran * max(self.total - self.done, 0.0)

    def _tty(self) -> bool:
        try:
            return self.stream.isatty()
        except (AttributeError, ValueError):
            return False

    def line(self, note: str = "") -> str:
        """The status line for the current state."""
        parts = [f"{self.label}:"]
        if self.total is not None and self.total > 0:
            frac = min(self.done / self.total, 1.0)
            parts.append(f"[{'#' * int(30 * frac):<30}] {100 * frac:5.1f}%")
        if self.unit:
            count = f"{self.done:g}" + (f"/{self.total:g}" if self.total is not None else "")
            parts.append(f"{count} {self.unit}")
        parts.append(f"{self.elapsed:5.0f} s")
        eta = self.eta()
        parts.append(f"eta {eta:5.0f} s" if eta is not None else "eta    -- s")
        if note:
            parts.append(note)
        return " ".join(parts)

    def update(self, done: float, note: str = "", force: bool = False) -> None:
        """Set the units done and redraw (throttled on a terminal; in a log
        at each tenth of the total, when `force`, or when complete)."""
        self.done = done
        if not self.enabled:
            return
        complete = self.total is not None and done >= self.total
        if self._tty():
            now = time.perf_counter()
            if not (force or complete) and now - self._last_draw < 0.5:
                return
            self._last_draw = now
            self.stream.write(f"\r{self.line(note)}   ")
            self._open = not complete
            if complete:
                self.stream.write("\n")
        else:
            tenth = (int(10 * done / self.total) if self.total is not None and self.total > 0
                     else -1)
            if not (force or complete or tenth > self._logged_tenth):
                return
            self._logged_tenth = max(tenth, self._logged_tenth)
            self.stream.write(self.line(note) + "\n")
        self.stream.flush()

    def step(self, note: str = "", by: float = 1.0) -> None:
        """One more unit finished (always shown: a step is an event)."""
        self.update(self.done + by, note, force=True)

    def skip(self, by: float = 1.0) -> None:
        """Units found already done (reused from an earlier run): counted
        as done, but not in the rate the time left is estimated from."""
        self.start += by
        self.done += by

    def setup_done(self) -> None:
        """The units done so far carried one-off work (a reference group's
        calibration in a blind run's first trial): the time left is
        estimated from the units after them.  Until one more unit is done
        no estimate is shown."""
        self.start = self.done
        self._rate_t0 = time.perf_counter()

    def say(self, text: str) -> None:
        """A message on its own line (the bar, if any, is kept above it)."""
        if not self.enabled:
            return
        if self._open:
            self.stream.write("\n")
            self._open = False
        self.stream.write(f"{self.label}: {text}\n")
        self.stream.flush()

    def close(self) -> None:
        """End an open bar line."""
        if self.enabled and self._open:
            self.stream.write("\n")
            self.stream.flush()
            self._open = False
