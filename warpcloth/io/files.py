"""File safety shared by every writer (USD export, sweep CSV, benchmark CSV and plot).

* :func:`check_output_path`: decide before any work whether an output path can be written: a
  name the file system takes, an existing folder, not a folder or a device, an existing file
  that may be replaced (not immutable), and a folder where a file can really be created (a
  temporary file is created and removed: ``os.access`` says yes to everything for root).
* :func:`temp_path`: temporaries are named ``.warpcloth-<pid>-<token><ext>`` beside their
  target, so :func:`sweep_stale_temporaries` can later recognise ours and remove those whose
  process is dead (a kill -9 leaves them; USD's own partial file during ``Save`` starts with
  the same name).
* :class:`AtomicFile` / :func:`write_atomic`: write a temporary, fsync, rename over the target;
  on any failure the temporary is removed and the target is left as it was.
* :class:`WriterLock`: one writer per results file (an ``flock`` on a lock file beside it).
* :class:`OutputError`: an output could not be written during the work (disk full, I/O error);
  the CLI prints it as one line and exits with :data:`EXIT_IO`.
* :func:`check_input_file` / :func:`read_input`: every file warpcloth reads (scenario files,
  meshes, the layers a USD file names) is a regular file of bounded size, checked before it is
  opened, never a FIFO, a device or a file of /proc, /sys or /dev (which block or never end),
  and opened without blocking.
"""

from __future__ import annotations

import csv
import ctypes
import errno
import hashlib
import io
import json
import math
import os
import re
import secrets
import shutil
import stat

from warpcloth.errors import WarpclothError

#: Prefix of every temporary file warpcloth creates beside a target.
TEMP_PREFIX = ".warpcloth-"
_TEMP_RE = re.compile(r"^\.warpcloth-(\d+)-")
#: Exit status when an output cannot be written during the work (sysexits.h EX_IOERR).
EXIT_IO = 74


class OutputError(WarpclothError):
    """An output could not be written during the work (disk full, I/O error)."""


def _name_max(folder: str) -> int:
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        return 255


def _path_max(folder: str) -> int:
    try:
        return os.pathconf(folder, "PC_PATH_MAX")
    except (OSError, ValueError):
        return 4096


def temp_path(target: str, ext: str | None = None) -> str:
    """A fresh temporary name beside ``target``: ``.warpcloth-<pid>-<token><ext>`` (``ext``
    defaults to the target's extension, which USD needs to pick its file format)."""
    folder = os.path.dirname(os.path.abspath(target))
    if ext is None:
        ext = os.path.splitext(target)[1]
    return os.path.join(folder, f"{TEMP_PREFIX}{os.getpid()}-{secrets.token_hex(4)}{ext}")


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return True  # not ours to judge
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return True
    return True


def sweep_stale_temporaries(folder: str, report=None) -> list[str]:
    """Remove ``.warpcloth-<pid>-*`` files in ``folder`` whose process is dead (left by a
    kill -9 or a power cut); says so in one line on ``report`` (a stream) when it removes any.
    Returns the removed paths. Files of live processes (this one included) are kept."""
    removed, freed = [], 0
    try:
        names = os.listdir(folder)
    except OSError:
        return removed
    for name in names:
        m = _TEMP_RE.match(name)
        if not m:
            continue
        pid = int(m.group(1))
        if pid == os.getpid() or _pid_alive(pid):
            continue
        path = os.path.join(folder, name)
        try:
            if os.path.islink(path):
                continue
            if os.path.isdir(path):  # a USD writer's folder of value clips (warpcloth.io.usd)
                size = sum(e.stat().st_size for e in os.scandir(path) if e.is_file())
                shutil.rmtree(path)
            elif os.path.isfile(path):
                size = os.path.getsize(path)
                os.unlink(path)
            else:
                continue
        except OSError:
            continue
        removed.append(path)
        freed += size
    if removed and report is not None:
        report.write(
            f"warpcloth: removed {len(removed)} stale temporary file(s) of dead warpcloth processes in "
            f"{folder} ({freed} bytes): {', '.join(os.path.basename(p) for p in removed)}\n"
        )
        report.flush()
    return removed


#: Folders of kernel files: "regular" files there block (/proc/kmsg), never end or change as read.
SPECIAL_FOLDERS = ("/proc", "/sys", "/dev")


def _size(n: int) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:,} bytes" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1024.0
    return f"{n:.3g} TiB"  # pragma: no cover


def _file_name(path, what: str) -> str:
    try:
        p = os.fspath(path)
    except TypeError:
        raise WarpclothError(f"{what} must be a file name, got {path!r:.80}") from None
    if isinstance(p, bytes):
        p = os.fsdecode(p)
    if not p:
        raise WarpclothError(f"{what} path is empty")
    if "\0" in p:
        raise WarpclothError(f"{what} path {p[:80]!r} contains a NUL character")
    return p


def _check_input_stat(p: str, st: os.stat_result, what: str, max_bytes: int | None) -> None:
    if stat.S_ISDIR(st.st_mode):
        raise WarpclothError(f"{what} {p!r} is a folder, not a file")
    if not stat.S_ISREG(st.st_mode):
        kind = "a FIFO" if stat.S_ISFIFO(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode) else "a device"
        raise WarpclothError(f"{what} {p!r} is {kind}, not a regular file")
    if max_bytes is not None and st.st_size > max_bytes:
        raise WarpclothError(f"{what} {p!r} is {_size(st.st_size)}, more than the {_size(max_bytes)} warpcloth reads")


def check_input_file(path, what: str = "input file", max_bytes: int | None = None) -> str:
    """Check, before opening it, that ``path`` names a file warpcloth may read: it exists, is a
    regular file (not a folder, FIFO, socket or device), not under /proc, /sys or /dev (their
    "regular" files block or never end), and at most ``max_bytes`` long; returns it.

    Raises:
        WarpclothError: one line naming the file and why it is refused.
    """
    p = _file_name(path, what)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        raise WarpclothError(f"{what} {p!r} does not exist") from None
    except OSError as exc:
        raise WarpclothError(f"cannot read {what} {p!r}: {exc.strerror or exc}") from None
    real = os.path.realpath(p)
    for folder in SPECIAL_FOLDERS:
        if real == folder or real.startswith(folder + os.sep):
            raise WarpclothError(f"{what} {p!r} is a system file under {folder}, not a regular file")
    _check_input_stat(p, st, what, max_bytes)
    return p


def read_input(path, what: str = "input file", max_bytes: int | None = None) -> bytes:
    """The bytes of a file :func:`check_input_file` accepts, opened without blocking (a file
    replaced by a FIFO after the check is refused, not waited on) and read up to ``max_bytes``."""
    p = check_input_file(path, what, max_bytes)
    try:
        fd = os.open(
            p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
        )
    except OSError as exc:
        raise WarpclothError(f"cannot read {what} {p!r}: {exc.strerror or exc}") from None
    try:
        _check_input_stat(p, os.fstat(fd), what, max_bytes)
        limit = max_bytes if max_bytes is not None else os.fstat(fd).st_size
        chunks, total = [], 0
        while True:
            chunk = os.read(fd, min(1 << 20, limit + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > limit:
                raise WarpclothError(f"{what} {p!r} grew past {_size(limit)} while it was read")
    except OSError as exc:
        raise WarpclothError(f"cannot read {what} {p!r}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    return b"".join(chunks)


def _check_name_and_parent(p: str, full: str, what: str) -> None:
    """The name fits the file system (each part, the whole path) and its parent is an existing folder."""
    folder = os.path.dirname(full)
    probe = folder
    while probe and not os.path.isdir(probe):
        parent = os.path.dirname(probe)
        probe = parent if parent != probe else ""
    name_max = _name_max(probe or "/")
    for part in full.split(os.sep):
        if len(os.fsencode(part)) > name_max:
            raise WarpclothError(
                f"{what} path {p!r}: the name {part[:40]!r}... is {len(os.fsencode(part))} bytes, "
                f"more than the {name_max} this file system allows"
            )
    path_max = _path_max(probe or "/")
    if len(os.fsencode(full)) >= path_max:
        raise WarpclothError(f"{what} path {p!r} is {len(os.fsencode(full))} bytes, more than the {path_max} allowed")
    if os.path.lexists(folder) and not os.path.isdir(folder):
        raise WarpclothError(f"{what} path {p!r}: {folder!r} is not a folder")
    if not os.path.isdir(folder):
        raise WarpclothError(f"{what} path {p!r}: folder {folder!r} does not exist")


def check_output_path(path: str, what: str = "output", extensions: tuple | None = None) -> str:
    """Check, before any work, that ``path`` can be written atomically; returns it.

    Raises:
        WarpclothError: one line naming the path and why it cannot be written.
    """
    try:
        p = os.fspath(path)
    except TypeError:
        raise WarpclothError(f"{what} path must be a file name, got {path!r:.80}") from None
    if not p:
        raise WarpclothError(f"{what} path is empty")
    if extensions is not None and os.path.splitext(p)[1].lower() not in extensions:
        raise WarpclothError(f"{what} path {p!r} must end in one of {', '.join(extensions)}")
    full = os.path.abspath(p)
    folder, _name = os.path.split(full)
    if os.path.isdir(full):
        raise WarpclothError(f"{what} path {p!r} is a folder, not a file")
    _check_name_and_parent(p, full, what)
    if os.path.lexists(full):
        if not os.path.isfile(full):
            raise WarpclothError(f"{what} path {p!r} exists and is not a regular file")
        try:  # an immutable or append-only file cannot be replaced (rename fails with EPERM)
            fd = os.open(full, os.O_WRONLY)
            os.close(fd)
        except OSError as exc:
            if exc.errno in (errno.EPERM, errno.EROFS):
                raise WarpclothError(
                    f"{what} path {p!r} cannot be replaced: {exc.strerror} "
                    "(an immutable or append-only file, or a read-only file system)"
                ) from None
    tmp = temp_path(full)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        raise WarpclothError(
            f"{what} path {p!r}: folder {folder!r} is not writable (creating a file there failed: "
            f"{exc.strerror or exc})"
        ) from None
    os.close(fd)
    try:
        os.unlink(tmp)
    except OSError:
        pass
    return p


def remove_temporary(tmp: str) -> None:
    """Remove ``tmp`` and any ``tmp.*`` a library made from its name (USD's safe-save file)."""
    folder, name = os.path.split(tmp)
    try:
        names = os.listdir(folder)
    except OSError:
        names = []
    for other in [name] + [n for n in names if n.startswith(name + ".")]:
        try:
            path = os.path.join(folder, other)
            if os.path.isdir(path) and not os.path.islink(path):
                shutil.rmtree(path)
            else:
                os.unlink(path)
        except FileNotFoundError:
            pass
        except OSError:
            pass


def fsync_dir(directory: str) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def describe_write_error(
    exc: OSError, target: str, what: str, needed: int | None = None, written: int | None = None
) -> str:
    """One line for a failed write: what, where, and how much was needed where known."""
    folder = os.path.dirname(os.path.abspath(target))
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        try:
            free = shutil.disk_usage(folder).free
        except OSError:
            free = None
        amounts = []
        if needed is not None:
            amounts.append(f"{needed} bytes needed")
        if written is not None:
            amounts.append(f"{written} bytes written before it filled")
        if free is not None:
            amounts.append(f"{free} bytes free")
        more = f" ({', '.join(amounts)})" if amounts else ""
        return f"no space left on the device of {folder} writing the {what} {target}{more}; {target} is unchanged"
    return f"cannot write the {what} {target}: {exc.strerror or exc}; {target} is unchanged"


class AtomicFile:
    """A temporary file beside ``path``, renamed over it on :meth:`commit`; :meth:`abort`
    (or any exception in a ``with`` block) removes it and leaves ``path`` as it was."""

    def __init__(self, path: str, what: str = "output", mode: str = "w", **open_kwargs):
        self.path = os.fspath(path)
        self.what = what
        self.tmp = temp_path(self.path)
        fd = os.open(self.tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        self.fh = os.fdopen(fd, mode, **open_kwargs)
        self.done = False

    def commit(self, needed: int | None = None) -> str:
        try:
            self.fh.flush()
            os.fsync(self.fh.fileno())
            self.fh.close()
            os.replace(self.tmp, self.path)
        except OSError as exc:
            written = os.path.getsize(self.tmp) if os.path.exists(self.tmp) else None
            self.abort()
            raise OutputError(describe_write_error(exc, self.path, self.what, needed=needed, written=written)) from None
        except BaseException:
            self.abort()
            raise
        self.done = True
        fsync_dir(os.path.dirname(os.path.abspath(self.path)))
        return self.path

    def abort(self) -> None:
        if self.done:
            return
        try:
            self.fh.close()
        except OSError:
            pass
        remove_temporary(self.tmp)
        self.done = True

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.commit()
        else:
            self.abort()
            if isinstance(exc, OSError) and not isinstance(exc, WarpclothError):
                raise OutputError(describe_write_error(exc, self.path, self.what)) from None


def write_atomic(path: str, data: str | bytes, what: str = "output") -> str:
    """Write ``data`` to ``path`` atomically (see :class:`AtomicFile`); raises
    :class:`OutputError` (the size needed, the target unchanged) when it cannot."""
    raw = data.encode("utf-8") if isinstance(data, str) else data
    try:
        f = AtomicFile(path, what, mode="wb")
    except OSError as exc:
        raise OutputError(describe_write_error(exc, path, what, needed=len(raw))) from None
    try:
        f.fh.write(raw)
    except OSError as exc:
        f.abort()
        raise OutputError(describe_write_error(exc, path, what, needed=len(raw))) from None
    except BaseException:
        f.abort()
        raise
    return f.commit(needed=len(raw))


# -- folders: outputs of many files (an OBJ sequence), built beside the target and renamed in --


def _foreign_entries(full: str, names) -> list[str]:
    """Entries of the existing folder ``full`` that are not regular files matching ``names``."""
    out = []
    with os.scandir(full) as entries:
        for e in entries:
            if not (names.match(e.name) and e.is_file(follow_symlinks=False)):
                out.append(e.name)
    return sorted(out)


def check_output_folder(path, what: str, names: re.Pattern) -> str:
    """Check, before any work, that the folder ``path`` can be written atomically (see
    :class:`AtomicFolder`); returns it. An existing ``path`` must be a real folder (not a link)
    holding only regular files whose names match ``names`` (a previous output of the same kind):
    replacing it must never delete anything else.

    Raises:
        WarpclothError: one line naming the path and why it cannot be written.
    """
    p = _file_name(path, what)
    full = os.path.abspath(p)
    if os.path.islink(full):
        raise WarpclothError(f"{what} path {p!r} is a link; warpcloth does not write through links")
    _check_name_and_parent(p, full, what)
    if os.path.lexists(full):
        if not os.path.isdir(full):
            raise WarpclothError(f"{what} path {p!r} exists and is not a folder")
        try:
            foreign = _foreign_entries(full, names)
        except OSError as exc:
            raise WarpclothError(f"{what} path {p!r}: cannot list the folder: {exc.strerror or exc}") from None
        if foreign:
            raise WarpclothError(
                f"{what} path {p!r} is a folder holding other files ({', '.join(repr(n) for n in foreign[:3])}"
                f"{', ...' if len(foreign) > 3 else ''}); warpcloth replaces only a folder of its own output: "
                "name a new or empty folder"
            )
    folder = os.path.dirname(full)
    tmp = temp_path(full, ext="")
    try:
        os.mkdir(tmp, 0o700)
    except OSError as exc:
        raise WarpclothError(
            f"{what} path {p!r}: folder {folder!r} is not writable (creating a folder there failed: "
            f"{exc.strerror or exc})"
        ) from None
    try:
        os.rmdir(tmp)
    except OSError:
        pass
    return p


#: renameat2(2) flag: swap two paths in one step (Linux 3.15+, glibc 2.28+).
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: str, b: str) -> bool:
    """Swap the paths ``a`` and ``b`` in one step where the system can (renameat2 RENAME_EXCHANGE);
    False where it cannot (no such call, or a file system without it)."""
    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), b)


def _replace_folder(tmp: str, target: str) -> None:
    """Put the folder ``tmp`` at ``target``: a rename where ``target`` is absent, else a swap in
    one step (or, without one, the old folder renamed aside first and put back if the second
    rename fails); the old folder is removed afterwards."""
    if not os.path.lexists(target):
        os.rename(tmp, target)
        return
    if _exchange(tmp, target):
        shutil.rmtree(tmp, ignore_errors=True)  # tmp now holds the old folder
        return
    old = temp_path(target, ext="")
    os.rename(target, old)
    try:
        os.rename(tmp, target)
    except BaseException:
        os.rename(old, target)
        raise
    shutil.rmtree(old, ignore_errors=True)


class AtomicFolder:
    """A temporary folder beside ``path`` (``.warpcloth-<pid>-<token>``, swept like a temporary
    file when its process dies) that a writer fills through :meth:`file`; :meth:`commit` puts it
    at ``path`` (replacing an older output there, checked by :func:`check_output_folder` with
    ``names``); :meth:`abort` removes it and leaves ``path`` as it was. A link at ``path`` is
    refused, never followed."""

    def __init__(self, path, what: str, names: re.Pattern):
        self.path = os.fspath(path)
        self.what = what
        self.names = names
        self.tmp = temp_path(self.path, ext="")
        try:
            os.mkdir(self.tmp, 0o755)
        except OSError as exc:
            raise OutputError(describe_write_error(exc, self.path, what)) from None
        self.done = False
        self.committed = False

    def file(self, name: str) -> str:
        """The path of the file ``name`` (one of ``names``) inside the folder being built."""
        if not self.names.match(name) or os.sep in name or (os.altsep and os.altsep in name):
            raise WarpclothError(f"{self.what}: {name!r} is not a file name this folder holds")
        return os.path.join(self.tmp, name)

    def commit(self) -> str:
        """Put the folder at ``path``; returns ``path``. On failure the folder is removed and
        ``path`` left as it was (:class:`OutputError`)."""
        if self.committed:
            return self.path
        if self.done:
            raise WarpclothError(f"the {self.what} {self.path} was aborted")
        try:
            check_output_folder(self.path, self.what, self.names)  # again: a link or a foreign file since
            for name in os.listdir(self.tmp):
                fd = os.open(os.path.join(self.tmp, name), os.O_RDONLY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
            fsync_dir(self.tmp)
            _replace_folder(self.tmp, self.path)
        except OSError as exc:
            self.abort()
            raise OutputError(describe_write_error(exc, self.path, self.what)) from None
        except BaseException:
            self.abort()
            raise
        self.done = self.committed = True
        fsync_dir(os.path.dirname(os.path.abspath(self.path)))
        return self.path

    def abort(self) -> None:
        if self.done:
            return
        shutil.rmtree(self.tmp, ignore_errors=True)
        self.done = True

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.commit()
        else:
            self.abort()


class WriterLock:
    """An exclusive lock on ``target`` for as long as a writer works on it: ``flock`` on a lock
    file beside it (``.NAME.lock``), holding the writer's pid. A second writer gets a
    :class:`~warpcloth.errors.WarpclothError` naming the holder's pid. The lock goes with the
    process (also on kill -9); the lock file is removed on :meth:`release`."""

    def __init__(self, target: str, what: str = "results file"):
        self.target = os.fspath(target)
        self.what = what
        folder, name = os.path.split(os.path.abspath(self.target))
        lock_name = f".{name}.lock"
        if len(os.fsencode(lock_name)) > _name_max(folder):
            lock_name = f".warpcloth-lock-{hashlib.sha1(os.fsencode(name)).hexdigest()[:16]}"
        self.path = os.path.join(folder, lock_name)
        self.fd: int | None = None

    def acquire(self) -> WriterLock:
        import fcntl  # noqa: PLC0415 (POSIX only)

        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise WarpclothError(
                    f"cannot lock the {self.what} {self.target}: cannot create {self.path}: {exc.strerror or exc}"
                ) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = ""
                try:
                    holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
                except OSError:
                    pass
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    who = f"pid {holder}" if holder else "another process"
                    raise WarpclothError(
                        f"{self.target} is being written by another warpcloth ({who}, lock {self.path}); "
                        "wait for it to finish or write elsewhere"
                    ) from None
                raise WarpclothError(f"cannot lock the {self.what} {self.target}: {exc.strerror or exc}") from None
            try:  # the file may have been removed by the previous holder between open and flock
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            try:  # the holder's pid, for the message a second writer gets (best effort: a full disk)
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            except OSError:
                pass
            self.fd = fd
            return self

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            os.unlink(self.path)  # while still holding it: a waiter re-checks the inode
        except OSError:
            pass
        os.close(self.fd)
        self.fd = None

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc):
        self.release()


__all__ = [
    "EXIT_IO",
    "TEMP_PREFIX",
    "AtomicFile",
    "AtomicFolder",
    "OutputError",
    "WriterLock",
    "check_input_file",
    "check_output_folder",
    "check_output_path",
    "describe_write_error",
    "fsync_dir",
    "read_input",
    "remove_temporary",
    "sweep_stale_temporaries",
    "temp_path",
    "write_atomic",
]


# -- CSV cells: one way for every results file (sweep, study, bench) --------------------------
def csv_cell(value) -> str:
    """A value as a CSV cell: None empty, booleans ``true``/``false``, floats at full precision
    (Python's shortest repr; ``inf``, ``nan``), dicts, lists and tuples as JSON."""

    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value, sort_keys=True)
    return str(value)


def csv_line(row: dict, columns) -> str:
    """One CSV line (with its newline) of ``row`` in ``columns`` order; missing columns are empty."""

    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([csv_cell(row.get(c)) for c in columns])
    return buf.getvalue()
