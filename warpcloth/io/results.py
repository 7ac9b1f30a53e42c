"""A durable results file: one CSV row per finished unit of work (a sweep's run, a study's
measurement), for the sweep (:mod:`warpcloth.lab.sweep`) and the study (:mod:`warpcloth.lab.study`).

* Created with its header atomically (:func:`~warpcloth.io.files.write_atomic`); each row is
  appended, flushed and fsync'd as its unit finishes, so a long sweep or study killed at any
  moment (kill -9 included) loses no finished row, at most a row cut short.
* One writer: a :class:`~warpcloth.io.files.WriterLock` is held from before the file is read or
  created until :meth:`ResultsFile.close`; a second writer is refused, naming the holder's pid.
* ``resume``: the whole file is validated first (UTF-8, this format's header, every row's cell
  count); a file refused is left exactly as it was. Then a cut last line (a kill) is copied
  beside the file (``NAME.dropped-<time>-<pid>``) and dropped; its unit runs again. The keys of
  the finished rows (and, with ``keep_rows``, the rows) are known before any work.
* ``-`` (where the format allows it): the rows go to stdout, without fsync and without resume.

:class:`ResultsFormat` names a file's columns and what its rows are (for the messages);
:func:`parse_cell` reads a cell back to a value.
"""

from __future__ import annotations

import csv
import io
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

from warpcloth.errors import WarpclothError
from warpcloth.io.files import (
    OutputError,
    WriterLock,
    check_output_path,
    csv_cell,
    csv_line,
    describe_write_error,
    sweep_stale_temporaries,
    write_atomic,
)


def parse_cell(text: str):
    """A CSV cell back to a value: '' -> None, true/false, int, float (inf, nan), else str."""
    if text == "":
        return None
    if text in ("true", "false"):
        return text == "true"
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        return text


@dataclass(frozen=True)
class ResultsFormat:
    """The layout of a results file.

    Attributes:
        columns: the header, in order.
        what: whose columns these are, in messages (``sweep``, ``study``).
        unit: what one row records, in messages (``run``, ``measurement``).
        parse: a cell back to a value (:func:`parse_cell`), or None to keep the text.
        key: the column that identifies a row (resume skips the keys already in the file).
        stdout: ``-`` writes the rows to stdout.
    """

    columns: tuple
    what: str
    unit: str
    parse: Callable | None = None
    key: str = "key"
    stdout: bool = False

    def format_row(self, row: dict) -> str:
        """One CSV line (with its newline) for ``row``; missing columns are empty."""
        return csv_line(row, self.columns)

    def header(self) -> str:
        return csv_line(dict(zip(self.columns, self.columns)), self.columns)

    def parse_row(self, cells: dict) -> dict:
        """A row of CSV cells (text) as values (unchanged without ``parse``)."""
        return cells if self.parse is None else {k: self.parse(v) for k, v in cells.items()}

    def as_written(self, row: dict) -> dict:
        """``row`` as reading it back from the file gives it (every column, cells parsed)."""
        return self.parse_row({k: csv_cell(row.get(k)) for k in self.columns})

    def read(self, path) -> list[dict]:
        """The rows of a results file as dicts (values parsed with ``parse``)."""
        with open(path, newline="", encoding="utf-8") as fh:
            return [self.parse_row(r) for r in csv.DictReader(fh)]


class ResultsFile:
    """A results file of ``fmt``: created with its header atomically, appended one fsync'd row
    at a time, locked from before it is read or created until :meth:`close`.

    Args:
        path: file path, or ``-`` for stdout (where ``fmt.stdout``).
        fmt: the file's :class:`ResultsFormat`.
        resume: continue an existing file (its keys are skipped); a missing file is created.
        overwrite: replace an existing file.
        report: stream for one-line notes (stale temporaries removed), or None.
        keep_rows: keep every row (as read back) in :attr:`done`, not only its key.

    Attributes:
        done_keys: keys of the rows in the file.
        done: key -> row (values parsed), with ``keep_rows``.
        rows: rows in the file.

    Raises:
        WarpclothError: the path cannot be written, is being written by another warpcloth,
            exists without ``resume``/``overwrite``, or is not a file of this format. In every
            such case the file is left exactly as it was.
    """

    def __init__(
        self,
        path: str,
        fmt: ResultsFormat,
        resume: bool = False,
        overwrite: bool = False,
        report=None,
        keep_rows: bool = False,
    ):
        self.path = str(path)
        self.format = fmt
        self.keep_rows = keep_rows
        self.done_keys: set[str] = set()
        self.done: dict[str, dict] = {}
        self.truncated = False
        self.dropped: bytes = b""  # the incomplete last line dropped on resume
        self.dropped_path: str | None = None  # where a copy of it was saved
        self.lock: WriterLock | None = None
        self.rows = 0
        if self.path == "-" and fmt.stdout:
            if resume:
                raise WarpclothError("--resume needs a results file, not stdout (-)")
            self.fh = sys.stdout
            self._fsync = False
            self._write(fmt.header())
            return
        self._fsync = True
        if os.path.isdir(self.path):
            raise WarpclothError(f"cannot write results to {self.path}: it is a directory")
        directory = os.path.dirname(os.path.abspath(self.path))
        if not os.path.isdir(directory):
            raise WarpclothError(f"cannot write results to {self.path}: directory {directory} does not exist")
        try:
            check_output_path(self.path, "results")
        except WarpclothError as exc:
            raise WarpclothError(f"cannot write results to {self.path}: {exc}") from None
        self.lock = WriterLock(self.path).acquire()
        try:
            sweep_stale_temporaries(directory, report)
            exists = os.path.exists(self.path) and os.path.getsize(self.path) > 0
            if exists and resume:
                self._read_existing()
            elif exists and not overwrite:
                raise WarpclothError(
                    f"{self.path} already exists: use --resume to continue it or --overwrite to replace it"
                )
            else:
                self._create()
            try:
                self.fh = open(self.path, "a", newline="", encoding="utf-8")
            except OSError as exc:
                raise WarpclothError(f"cannot write results to {self.path}: {exc.strerror or exc}") from None
        except BaseException:
            self.lock.release()
            raise

    def _create(self) -> None:
        try:
            write_atomic(self.path, self.format.header(), "results CSV")
        except OutputError as exc:
            raise WarpclothError(str(exc)) from None

    def _read_existing(self) -> None:
        """Validate the whole file first; change it (drop a cut last line) only once it is
        known to be ours and the resume goes ahead."""
        fmt, columns = self.format, list(self.format.columns)
        try:
            with open(self.path, "rb") as fh:
                data = fh.read()
        except OSError as exc:
            raise WarpclothError(f"cannot read {self.path} to resume: {exc.strerror or exc}") from None
        cut = data.rfind(b"\n") + 1
        if cut == 0:
            raise WarpclothError(f"cannot resume {self.path}: it has no complete header line (left unchanged)")
        complete, tail = data[:cut], data[cut:]
        try:
            text = complete.decode("utf-8")
        except UnicodeDecodeError:
            raise WarpclothError(f"cannot resume {self.path}: not UTF-8 text (left unchanged)") from None
        reader = csv.reader(io.StringIO(text))
        if next(reader, None) != columns:
            raise WarpclothError(
                f"cannot resume {self.path}: its header is not this warpcloth's {fmt.what} columns "
                "(another program, or another warpcloth version, wrote it); left unchanged"
            )
        k = columns.index(fmt.key)
        keys, rows = set(), {}
        for line_no, cells in enumerate(reader, start=2):
            if len(cells) != len(columns):
                raise WarpclothError(
                    f"cannot resume {self.path}: line {line_no} has {len(cells)} cells, "
                    f"expected {len(columns)} (left unchanged)"
                )
            keys.add(cells[k])
            if self.keep_rows:
                rows[cells[k]] = fmt.parse_row(dict(zip(columns, cells)))
        if tail:  # a row cut short by a kill: keep a copy, drop it; its unit runs again
            self.dropped = tail
            side = f"{self.path}.dropped-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}-{os.getpid()}"
            try:
                write_atomic(side, tail, "copy of the dropped line")
                self.dropped_path = side
            except (OSError, WarpclothError):
                self.dropped_path = None  # the bytes are shown in the message instead
            try:
                os.truncate(self.path, cut)
            except OSError as exc:
                raise WarpclothError(f"cannot resume {self.path}: {exc.strerror or exc}") from None
            self.truncated = True
        self.done_keys = keys
        self.done = rows
        self.rows = len(keys)

    def dropped_note(self) -> str:
        """One line about the dropped incomplete last line (empty if none)."""
        if not self.truncated:
            return ""
        where = f"a copy is in {self.dropped_path}" if self.dropped_path else f"it was {self.dropped[:120]!r}"
        return (
            f"{self.path}: dropped an incomplete last line ({len(self.dropped)} bytes, "
            f"a {self.format.unit} cut short; {where}); it runs again"
        )

    def _write(self, text: str) -> None:
        try:
            self.fh.write(text)
            self.fh.flush()
            if self._fsync:
                os.fsync(self.fh.fileno())
        except BrokenPipeError:
            raise
        except OSError as exc:
            if self.fh is sys.stdout:
                err = OutputError(f"cannot write the CSV to stdout: {exc.strerror or exc}")
                err.stdout = True
                raise err from None
            line = describe_write_error(exc, self.path, "results CSV", needed=len(text.encode("utf-8")))
            line = line.replace(f"; {self.path} is unchanged", "")
            raise OutputError(
                f"{line}; the {self.rows} rows before it are kept (a cut last row is dropped on --resume)"
            ) from None

    def write(self, row: dict) -> None:
        """Append ``row`` and force it to disk."""
        self._write(self.format.format_row(row))
        self.rows += 1
        key = csv_cell(row.get(self.format.key))
        self.done_keys.add(key)
        if self.keep_rows:
            self.done[key] = self.format.as_written(row)

    def close(self) -> None:
        try:
            if self.fh is not sys.stdout:
                try:
                    self.fh.close()
                except OSError:
                    pass
        finally:
            if self.lock is not None:
                self.lock.release()


__all__ = ["ResultsFile", "ResultsFormat", "parse_cell"]
