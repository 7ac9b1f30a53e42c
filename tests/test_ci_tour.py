"""The CI's wheel tour (.ci/tour.sh) covers the README's tour: every command line of README.md's
"A tour of the CLI" block has a line in the script, in the same order (same command and first
argument; the script's are short variants, with fewer frames and smaller sheets)."""

import re
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _readme_tour() -> list[str]:
    text = (REPO / "README.md").read_text()
    block = text.split("## A tour of the CLI", 1)[1].split("```sh", 1)[1].split("```", 1)[0]
    return [line.split("#", 1)[0].strip() for line in block.strip().splitlines() if line.strip()]


def _key(command: str) -> tuple:
    words = command.replace("python -m warpcloth ", "warpcloth ").split()
    return tuple(words[:3]) if words[:2] == ["warpcloth", "run"] or words[:1] == ["python"] else tuple(words[:2])


def test_every_readme_tour_line_runs_in_the_ci_tour():
    script = [m.group(1) for m in re.finditer(r"^say (.+)$", (REPO / ".ci" / "tour.sh").read_text(), re.M)]
    keys = [_key(s) for s in script]
    position = 0
    for line in _readme_tour():
        key = _key(line)
        assert key in keys[position:], f"README tour line not in .ci/tour.sh (in order): {line}"
        position = keys.index(key, position) + 1


def _tour_commands() -> list[str]:
    """The tour script's command lines (backslash continuations joined), without the leading ``say``."""
    text = (REPO / ".ci" / "tour.sh").read_text().replace("\\\n", " ")
    return [m.group(1) for m in re.finditer(r"^say (.+)$", text, re.M)]


def test_every_warpcloth_line_of_the_ci_tour_parses_with_todays_flags():
    # the tour runs only in CI, after a wheel build; a flag renamed or removed (the study's
    # --accuracy-sizes) stopped it there with "unrecognized arguments" while every test passed
    import shlex

    import pytest

    from warpcloth.cli import build_parser

    commands = 0
    for line in _tour_commands():
        words = shlex.split(line)
        if words[:3] == ["python", "-m", "warpcloth"]:
            words = words[3:]
        elif words[:1] == ["warpcloth"]:
            words = words[1:]
        else:
            continue  # python -m warpcloth.examples / .scenarios.flag: their own parsers
        commands += 1
        try:
            build_parser((words[0],) if not words[0].startswith("-") else ()).parse_args(words)
        except SystemExit as exc:
            if exc.code != 0:  # --version exits 0
                pytest.fail(f".ci/tour.sh line does not parse: {line}")
    assert commands > 20


def test_ci_runs_the_readme_test_command_as_written_and_keeps_the_slowest_tests():
    text = (REPO / "README.md").read_text()
    block = text.split("Run the tests", 1)[1].split("```sh", 1)[1].split("```", 1)[0].strip()
    assert block.count("\n") == 0 and "pytest" in block and "--durations=30" in block, block
    run = [line for line in (REPO / ".ci" / "run").read_text().splitlines() if "pytest" in line and line[:1] != "#"]
    assert len(run) == 1 and run[0] == block + " | tee test-durations.txt", run
    assert "test-durations.txt" in (REPO / ".gitignore").read_text().splitlines()
