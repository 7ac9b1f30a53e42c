"""Progress with an ETA on stderr: one :class:`Progress` for every command (``run``, ``max-dt``,
``bench``, ``sweep``, ``study``).

On a terminal: one line redrawn in place (at most 5 times a second unless forced) and, at the
end, cleared (or kept, with ``keep=True``: the sweep's and the study's last bar stays).
Otherwise (a log file, a pipe, CI): plain lines, at most one every :data:`PLAIN_INTERVAL`
seconds and none for work shorter than that, so short runs print nothing; a forced update
always prints. ``--quiet`` turns it off.

The line is the default layout (:meth:`Progress.text`) or a caller's ``layout(progress, done,
total, note, unit)``, built from the same pieces: :meth:`Progress.bar`, :meth:`Progress.eta`,
:meth:`Progress.elapsed`, :func:`format_seconds` and :func:`format_clock`.
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
    """``5 s``, ``1 min 05 s``, ``2 h 03 min``; ``?`` for a negative or NaN value."""
    if s != s or s < 0:
        return "?"
    if s < 60:
        return f"{s:.0f} s"
    if s < 3600:
        return f"{int(s // 60)} min {int(s % 60):02d} s"
    return f"{int(s // 3600)} h {int(s % 3600 // 60):02d} min"


def format_clock(seconds: float) -> str:
    """A duration as a clock, ``m:ss`` or ``h:mm:ss`` (negative values read as 0)."""
    s = max(0, int(round(seconds)))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


class Progress:
    """``update(done, total, note)``: ``done`` of ``total`` units (simulated seconds, trials,
    combinations, runs, particle-weighted groups); the ETA is the elapsed wall time scaled to
    what is left.

    Args:
        label: the first word of the default line.
        stream: where the line goes (default stderr).
        enabled: False: nothing is ever written (``--quiet``).
        tty: redraw in place (default: whether ``stream`` is a terminal).
        clock: seconds, monotonic (injectable for tests).
        layout: ``layout(progress, done, total, note, unit) -> str``; default :meth:`text`.
        keep: on a terminal, end the last line with a newline at :meth:`close` instead of clearing it.
    """

    def __init__(
        self,
        label: str = "",
        stream=None,
        enabled: bool = True,
        tty: bool | None = None,
        clock=time.monotonic,
        layout=None,
        keep: bool = False,
    ):
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.tty = _isatty(self.stream) if tty is None else tty
        self.clock = clock
        self.layout = layout
        self.keep = keep
        self.start = clock()
        self.last = self.start
        self.width = 0

    def elapsed(self) -> float:
        """Wall seconds since the start."""
        return self.clock() - self.start

    def eta(self, done: float, total: float | None) -> float | None:
        """Wall seconds left, from the rate so far (None before any work is done)."""
        elapsed = self.elapsed()
        if not total or done <= 0 or elapsed <= 0:
            return None
        return elapsed * max(0.0, total - done) / done

    @staticmethod
    def bar(fraction: float, width: int = 20, empty: str = ".") -> str:
        """``[####....]``: ``fraction`` (clipped to [0, 1]) of ``width`` cells filled."""
        filled = int(width * min(1.0, max(0.0, fraction)))
        return "[" + "#" * filled + empty * (width - filled) + "]"

    def text(self, done: float, total: float | None, note: str = "", unit: str = "") -> str:
        """The default line: label, bar (on a terminal), percent, count, note, elapsed, ETA."""
        if self.layout is not None:
            return self.layout(self, done, total, note, unit)
        parts = [self.label]
        if total:
            frac = min(1.0, max(0.0, done / total))
            if self.tty:
                parts.append(self.bar(frac))
            parts.append(f"{100 * frac:3.0f}%")
            parts.append(f"{done:.4g}/{total:.4g}{unit}")
        if note:
            parts.append(note)
        parts.append(f"elapsed {format_seconds(self.elapsed())}")
        eta = self.eta(done, total)
        if eta is not None:
            parts.append(f"ETA {format_seconds(eta)}")
        return " ".join(parts)

    def update(
        self, done: float, total: float | None = None, note: str = "", unit: str = "", force: bool = False
    ) -> None:
        """Show the line for ``done`` of ``total``, unless one was shown too recently (``force``: show it)."""
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
        self.last = now
        try:
            self.stream.flush()
        except (OSError, ValueError):
            pass

    def close(self) -> None:
        """End the terminal line: cleared, or kept (``keep``)."""
        if self.enabled and self.tty and self.width:
            self.stream.write("\n" if self.keep else "\r" + " " * self.width + "\r")
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


__all__ = ["PLAIN_INTERVAL", "TTY_INTERVAL", "Progress", "RunProgress", "format_clock", "format_seconds"]
