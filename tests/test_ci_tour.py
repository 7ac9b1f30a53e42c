"""The CI's wheel tour (.ci/tour.sh) is the README's tour as printed: between its markers, one line
per line of README.md's "A tour of the CLI" block, in order, each word the README's but for the values
of the flags that shorten a run (:data:`SHORTENED`); the wheel is installed with the extras that the
README's install line names; no tour line writes a results file an earlier one wrote (sweep and study
refuse to overwrite)."""

import re
import shlex
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
#: The flags whose values a CI tour line may add, change or drop: sizes (``--sizes``: the bench's and the
#: study's), frame and step counts, durations; every other word is the README's.
SHORTENED = ("--size", "--rows", "--cols", "--sizes", "--num-frames", "--steps", "--duration")
BEGIN, END = "# -- README.md's tour --", "# -- end of README.md's tour --"
#: The lines that open and close the tour's two streams (.ci/tour.sh runs them side by side).
STREAM_FRAMES = ("first() {", "}", "second() {")


def _readme_tour() -> list[str]:
    """The tour block's command lines, comments dropped."""
    text = (REPO / "README.md").read_text()
    block = text.split("## A tour of the CLI", 1)[1].split("```sh", 1)[1].split("```", 1)[0]
    return [shlex.join(shlex.split(line, comments=True)) for line in block.splitlines() if line.strip()]


def _ci_tour_section() -> list[str]:
    """.ci/tour.sh's lines between its markers (continuations joined), without the leading ``say``;
    any other line there (a ``cd``, an ``rm``: the tour as printed would not have it) fails but the
    frames of its two streams (``first() {``, ``second() {``, ``}``: functions the script runs side by
    side, each in order)."""
    text = (REPO / ".ci" / "tour.sh").read_text().replace("\\\n", " ")
    assert text.count(BEGIN) == 1 and text.count(END) == 1, "the tour's markers in .ci/tour.sh"
    lines = [line.strip() for line in text.split(BEGIN, 1)[1].split(END, 1)[0].splitlines()]
    lines = [line for line in lines if line and not line.startswith("#") and line not in STREAM_FRAMES]
    stray = [line for line in lines if not line.startswith("say ")]
    assert not stray, f".ci/tour.sh runs lines the README's tour does not print: {stray}"
    return [line[len("say ") :] for line in lines]


def unshortened(command: str) -> list[str]:
    """The command's words without the :data:`SHORTENED` flags and their values."""
    words, out, k = shlex.split(command), [], 0
    while k < len(words):
        flag = words[k].split("=", 1)[0]
        if flag in SHORTENED:
            k += 1 if "=" in words[k] else 2
            continue
        out.append(words[k])
        k += 1
    return out


def test_unshortened_keeps_every_other_word():
    assert unshortened("warpcloth run sheet --rows 64 --cols 64 --duration 2 --json") == [
        "warpcloth",
        "run",
        "sheet",
        "--json",
    ]
    assert unshortened("warpcloth run sheet --size=8 --num-frames 2") == ["warpcloth", "run", "sheet"]
    # what the tour had differ from the README: a dropped flag, another output name, an extra integrator list
    assert unshortened("warpcloth run cusick --material denim") != unshortened("warpcloth run cusick --size 8")
    assert unshortened("sweep --example quick --out quick.csv") != unshortened("sweep --example quick --out quick2.csv")
    assert unshortened("warpcloth study --profile quick") != unshortened(
        "warpcloth study --profile quick --integrators xpbd"
    )


def test_the_ci_tour_is_the_readme_tour_line_for_line():
    readme, ci = _readme_tour(), _ci_tour_section()
    for k, (printed, run) in enumerate(zip(readme, ci)):
        assert unshortened(printed) == unshortened(run), (
            f"README tour line {k + 1} and .ci/tour.sh differ beyond {', '.join(SHORTENED)}:\n  {printed}\n  {run}"
        )
    assert len(ci) == len(readme), f"README's tour has {len(readme)} lines, .ci/tour.sh's section {len(ci)}"


def test_no_tour_line_writes_a_results_file_an_earlier_one_wrote():
    # sweep and study refuse an existing results file or folder (without --resume or --overwrite): the tour's
    # second sweep wrote quick.csv again and stopped there
    seen = {}
    for line in _readme_tour():
        words = shlex.split(line)
        words = words[2:] if words[:3] == ["python", "-m", "warpcloth"] else words
        if words[1:2] not in (["sweep"], ["study"]) or {"--resume", "--overwrite"} & set(words):
            continue
        for flag in ("--out", "-o"):
            if flag in words:
                target = words[words.index(flag) + 1]
                assert target not in seen, f"{line!r} writes {target}, which {seen[target]!r} wrote"
                seen[target] = line
    assert len(seen) >= 3


def _extras(text: str) -> set:
    return {e.strip() for group in re.findall(r"\[([a-z, ]+)\]", text) for e in group.split(",")}


def test_the_wheel_is_installed_with_the_extras_the_readme_names():
    readme = (REPO / "README.md").read_text()
    wheel = readme.split("From a wheel, in an empty folder:", 1)[1].split("\n\n", 1)[0]
    installs = re.findall(r"`pip install ([^`]+)`", wheel)
    assert len(installs) == 2 and len({frozenset(_extras(i)) for i in installs}) == 1, installs
    named = _extras(installs[0])
    ci = [line for line in (REPO / ".ci" / "run").read_text().splitlines() if "tour/venv/bin/pip" in line]
    assert len(ci) == 1 and _extras(ci[0]) == named, (ci, named)
    # what the tour's lines need: matplotlib draws bench --plot and run --preview (the plot extra)
    tour = " ".join(_readme_tour())
    if "--plot" in tour or "--preview" in tour:
        assert "plot" in named


def _tour_commands() -> list[str]:
    """The tour script's command lines (backslash continuations joined), without the leading ``say``."""
    text = (REPO / ".ci" / "tour.sh").read_text().replace("\\\n", " ")
    return [m.group(1) for m in re.finditer(r"^say (.+)$", text, re.M)]


def test_every_warpcloth_line_of_the_ci_tour_parses_with_todays_flags():
    # the tour runs only in CI, after a wheel build; a flag renamed or removed (the study's
    # --accuracy-sizes) stopped it there with "unrecognized arguments" while every test passed
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
