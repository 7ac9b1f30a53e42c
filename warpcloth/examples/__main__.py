"""``python -m warpcloth.examples [DIR]``: copy the shipped examples (the XML test lists, the cape
mesh and its scenario file) into DIR (default ``./examples``), so that the README's commands
(``warpcloth sweep examples/quick.xml``, ``warpcloth run mesh --mesh examples/cape.obj``, ...) run
from any folder after ``pip install warpcloth``.

Each file is written through :func:`~warpcloth.io.files.write_atomic` (a temporary beside it,
renamed over it: a full disk leaves no half file). An existing file identical to the shipped one
is kept; one that is a cut-short copy of it (a full disk under an older copier) is replaced;
one that differs otherwise (edited) is kept, and ``--force`` replaces it. A link, a folder or a
device where a file goes is refused, never written through. Bad input: one line, exit 2; a
write that fails (a full disk): one line, exit 74."""

import argparse
import errno
import os
import sys

from warpcloth.errors import WarpclothError
from warpcloth.io.files import EXIT_IO, OutputError, check_output_path, read_input, write_atomic

#: The example files, by kind (``warpcloth list --examples`` prints them).
KINDS = {".xml": "test list", ".obj": "mesh", ".toml": "scenario file"}
#: Exit status of bad input (as every warpcloth command).
EXIT_USAGE = 2
#: Folders of kernel files: nothing is written there.
SPECIAL_FOLDERS = ("/proc", "/sys", "/dev")
#: The largest shipped example [bytes] (an existing file is compared with it, read up to this).
MAX_EXAMPLE_BYTES = 2**24


def example_files() -> list[tuple[str, str]]:
    """(kind, path) of every shipped example file, by kind then name."""
    here = os.path.dirname(os.path.abspath(__file__))
    files = [
        (KINDS[os.path.splitext(n)[1]], os.path.join(here, n))
        for n in os.listdir(here)
        if os.path.splitext(n)[1] in KINDS
    ]
    order = list(KINDS.values())
    return sorted(files, key=lambda f: (order.index(f[0]), f[1]))


class _Parser(argparse.ArgumentParser):
    """Errors as one line, ``warpcloth: error: ...``, status 2 (as ``warpcloth``'s own parser)."""

    def error(self, message):
        self.exit(EXIT_USAGE, f"warpcloth: error: {message}\n")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="python -m warpcloth.examples",
        description="Copy the shipped examples (test lists, cape.obj, cape.toml) into a folder.",
    )
    p.add_argument("folder", nargs="?", default="examples", help="the folder to copy them into (default ./examples)")
    p.add_argument("--force", action="store_true", help="replace existing files that differ from the shipped ones")
    return p


def _check_folder(folder: str) -> str:
    """The folder's path, refused when it cannot hold the examples (before anything is written)."""
    if not folder:
        raise WarpclothError("the examples folder path is empty")
    if "\0" in folder:
        raise WarpclothError(f"the examples folder path {folder[:80]!r} contains a NUL character")
    real = os.path.realpath(folder)
    for special in SPECIAL_FOLDERS:
        if real == special or real.startswith(special + os.sep):
            raise WarpclothError(f"examples folder {folder!r} is under {special}, where warpcloth writes nothing")
    if os.path.lexists(folder) and not os.path.isdir(folder):
        raise WarpclothError(f"examples folder {folder!r} exists and is not a folder")
    return folder


def _make_folder(folder: str) -> None:
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        message = f"cannot create the examples folder {folder!r}: {exc.strerror or exc}"
        if exc.errno in (errno.ENOSPC, errno.EDQUOT, errno.EIO):
            raise OutputError(message) from None
        raise WarpclothError(message) from None


def _plan(folder: str, force: bool) -> list[tuple[str, str, bytes, str]]:
    """(target, kind, shipped bytes, what to do) for every example: "copy", "replace" or "keep"."""
    plan = []
    for kind, path in example_files():
        with open(path, "rb") as fh:
            data = fh.read()
        target = os.path.join(folder, os.path.basename(path))
        if os.path.islink(target):
            raise WarpclothError(f"{target} is a link; warpcloth does not write through links: remove it first")
        if not os.path.lexists(target):
            plan.append((target, kind, data, "copy"))
            continue
        try:
            have = read_input(target, "example file", MAX_EXAMPLE_BYTES)
        except WarpclothError as exc:
            raise WarpclothError(f"{exc}; it is where the example {os.path.basename(path)} goes") from None
        if have == data:
            plan.append((target, kind, data, "keep"))
        elif data.startswith(have):  # a cut-short copy (a full disk under an older copier)
            plan.append((target, kind, data, f"replace: a cut-short copy, {len(have):,} of {len(data):,} bytes"))
        elif force:
            plan.append((target, kind, data, "replace: it differed from the shipped file (--force)"))
        else:
            plan.append((target, kind, data, "differs"))
    return plan


def copy_examples(folder: str, force: bool = False, out=None) -> list[str]:
    """Copy the shipped examples into ``folder`` (see the module docstring); one line per file on
    ``out`` (default stdout). Returns the paths written.

    Raises:
        WarpclothError: a folder or a target that cannot be written, before anything is written;
        OutputError: a write that failed (a full disk), the target left as it was.
    """
    out = out or sys.stdout
    folder = _check_folder(folder)
    _make_folder(folder)
    plan = _plan(folder, force)
    for target, _kind, _data, action in plan:
        if action.startswith(("copy", "replace")):
            check_output_path(target, "example file")
    written = []
    for target, kind, data, action in plan:
        if action == "keep":
            print(f"kept     {target} (identical to the shipped {kind})", file=out)
        elif action == "differs":
            print(f"kept     {target} (differs from the shipped {kind}; --force replaces it)", file=out)
        else:
            write_atomic(target, data, what="example file")
            written.append(target)
            verb = "copied  " if action == "copy" else "replaced"
            why = f"{kind}" if action == "copy" else f"{kind}; {action.split(': ', 1)[1]}"
            print(f"{verb} {target} ({why})", file=out)
    return written


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:  # --help (0) or a usage error (2, its line already printed)
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    try:
        copy_examples(args.folder, force=args.force)
    except OutputError as exc:
        print(f"warpcloth: error: {exc}", file=sys.stderr)
        return EXIT_IO
    except WarpclothError as exc:
        print(f"warpcloth: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    return 0


if __name__ == "__main__":
    sys.exit(main())
