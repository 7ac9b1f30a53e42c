# ruff: noqa
# One-off audit script of issues 26, 30 and 31 (2026-12-03, branch audit); outputs in bench/results/audit-26-30-31.txt.
"""Every `warpcloth ...` command in README.md and docs/*.md (code blocks and inline code) parsed with today's CLI."""

import contextlib
import io
import pathlib
import re
import shlex

from warpcloth.cli import build_parser

root = pathlib.Path(__file__).resolve().parents[2]
bad = 0
n = 0
for f in [root / "README.md", *sorted((root / "docs").rglob("*.md"))]:
    text = f.read_text()
    cands = []
    for block in re.findall(r"```(?:sh|bash|shell|console)?\n(.*?)```", text, re.S):
        block = block.replace("\\\n", " ")
        cands += [l.strip().lstrip("$ ").split("  #")[0].split(" # ")[0] for l in block.splitlines()]
    cands += re.findall(r"`((?:python -m )?warpcloth [^`]+)`", text)
    for c in cands:
        c = c.strip()
        if c.startswith("python -m warpcloth "):
            c = c[len("python -m ") :]
        if not c.startswith("warpcloth ") or "..." in c or "|" in c.split("warpcloth", 1)[1][:3]:
            continue
        try:
            words = shlex.split(c)[1:]
        except ValueError:
            continue
        if not words or any(w in ("...", "[...]") or w.startswith("[") or w.isupper() and len(w) > 2 for w in words):
            # placeholders such as DIR, FILE.toml are fine for the parser; only skip bracketed optional syntax
            if any(w.startswith("[") for w in words):
                continue
        n += 1
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                build_parser((words[0],) if not words[0].startswith("-") else ()).parse_args(words)
        except SystemExit as e:
            if e.code != 0:
                bad += 1
                print(f"{f.relative_to(root)}: {c}\n    -> {err.getvalue().strip().splitlines()[-1]}")
print(f"{n} commands parsed, {bad} refused")
