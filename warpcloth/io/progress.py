"""Progress with an ETA on stderr for ``run``, ``max-dt`` and ``bench``.

On a terminal: one line redrawn in place (at most 5 times a second) and cleared at the end.
Otherwise (a log file, a pipe, CI): plain lines, at most one every :data:`PLAIN_INTERVAL`
seconds and none for work shorter than that, so short runs print nothing. ``--quiet`` turns
it off.
"""

from __future__ import annotations

import sys
import time

#: Seconds between plain progress lines (stderr not a terminal).
PLAIN_INTERVAL = 5.0
#: Seconds between redraws on a terminal.
TTY_INTERVAL = 0.2


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):
        return False


def format_seconds(s: float) -> str:
    if s != s or s < 0:
        return "?"
    if s < 60:
        return f"{s:.0f} s"
    if s < 3600:
        return f"{int(s // 60)} min {int(s % 60):02d} s"
    return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"


class Progress:
    """``update(done, total, note)``: ``done`` of ``total`` units (simulated seconds, trials,
    combinations); the ETA is the elapsed wall time scaled to what is left."""

    def __init__(self, label: str, stream=None, enabled: bool = True, tty: bool | None = None, clock=time.monotonic):
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.tty = _isatty(self.stream) if tty is None else tty
        self.clock = clock
        self.start = clock()
        self.last = self.start
        self.width = 0
        self.lines = 0

    def eta(self, done: float, total: float | None) -> float | None:
        elapsed = self.clock() - self.start
        if not total or done <= 0 or elapsed <= 0:
            return None
        return elapsed * max(0.0, total - done) / done

    def text(self, done: float, total: float | None, note: str = "", unit: str = "") -> str:
        elapsed = self.clock() - self.start
        parts = [self.label]
        if total:
            frac = min(1.0, max(0.0, done / total))
            if self.tty:
                bar = int(20 * frac)
                parts.append("[" + "#" * bar + "." * (20 - bar) + "]")
            parts.append(f"{100 * frac:3.0f}%")
            parts.append(f"{done:.4g}/{total:.4g}{unit}")
        if note:
            parts.append(note)
        parts.append(f"elapsed {format_seconds(elapsed)}")
        eta = self.eta(done, total)
        if eta is not None:
            parts.append(f"ETA {format_seconds(eta)}")
        return " ".join(parts)

    def update(self, done: float, total: float | None = None, note: str = "", unit: str = "", force: bool = False) -> None:
        if not self.enabled:
            return
        now = self.clock()
        if self.tty:
            if not force and now - self.last < TTY_INTERVAL:
                return
            line = self.text(done, total, note, unit)
            pad = max(0, self.width - len(line))
            self.stream.write("\r" + line + " " * pad)
            self.width = len(line)
        else:
            if not force and (now - self.last < PLAIN_INTERVAL):
                return
            self.stream.write(self.text(done, total, note, unit) + "\n")
            self.lines += 1
        self.last = now
        try:
            self.stream.flush()
        except (OSError, ValueError):
            pass

    def close(self) -> None:
        if self.enabled and self.tty and self.width:
            self.stream.write("\r" + " " * self.width + "\r")
            self.stream.flush()
            self.width = 0


class RunProgress:
    """A frame writer (see :class:`~warpcloth.io.frames.FrameSinks`) that reports simulated time
    against the run's duration (a sheet may stop earlier, at equilibrium)."""

    def __init__(self, duration: float, label: str = "run", stream=None, tty: bool | None = None):
        self.duration = float(duration)
        self.progress = Progress(label, stream, tty=tty)

    def write_frame(self, points, sim_time: float | None = None) -> None:
        if sim_time is not None:
            self.progress.update(sim_time, self.duration, unit=" s simulated")

    def close(self):
        self.progress.close()
        return None

    def abort(self) -> None:
        self.progress.close()
