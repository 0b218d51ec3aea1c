"""The user docs name only commands and options that exist: every `dronectl <command> [<sub>] --option`
written in README.md or docs/**/*.md (in a code span or a code block) is checked against that command's
own `--help`, and every relative link against the file (and heading) it points to. Docs drift when a
command, an option or a page is renamed; this is where it shows.

A line that holds `PLACEHOLDER` (a feature another branch is adding) is not checked.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import re
from functools import cache
from pathlib import Path

import pytest
from dronectl.bench_cmd import BENCHMARKS
from dronectl.cli import COMMANDS

REPO = Path(__file__).resolve().parents[1]
DOCS = (REPO / "README.md", *sorted((REPO / "docs").rglob("*.md")))
SUBCOMMANDS = {"bench": tuple(BENCHMARKS), "missions": ("run",), "dataset": ("check",)}
COMMAND = re.compile(r"\bdronectl\s+((?:--debug\s+)?[a-z][a-z0-9-]*)((?:\s+[^\s|;&#`]+)*)")
OPTION = re.compile(r"(?<![\w-])(--[a-z][a-z0-9-]*)")


def command_lines(text: str) -> list[str]:
    """Every piece of text that may hold a `dronectl` command line: code spans and code-block lines
    (a block's line continued with a backslash joins the next one); placeholder lines left out."""
    text = "\n".join(line for line in text.splitlines() if "PLACEHOLDER" not in line)
    pieces: list[str] = []
    for block in re.findall(r"```[^\n]*\n(.*?)```", text, flags=re.S):
        pieces += block.replace("\\\n", " ").splitlines()
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    pieces += re.findall(r"`([^`\n]+)`", prose)
    return [p.split("#")[0] for p in pieces]


@cache
def help_text(argv: tuple[str, ...]) -> str:
    """What `dronectl <argv> --help` prints, run in this process (each command parses with argparse)."""
    module = importlib.import_module(COMMANDS[argv[0]][0])
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        module.main([*argv[1:], "--help"])
    return out.getvalue()


def wrong_names(doc: Path) -> list[str]:
    """The commands and options `doc` names that `dronectl` does not have, each with its line."""
    wrong = []
    for piece in command_lines(doc.read_text()):
        for match in COMMAND.finditer(piece):
            name, rest = match.group(1).removeprefix("--debug").strip(), match.group(2).split()
            if name not in COMMANDS:
                wrong.append(f"unknown command `dronectl {name}`: {piece.strip()}")
                continue
            argv: tuple[str, ...] = (name,)
            if name in SUBCOMMANDS and rest and not rest[0].startswith(("-", "<")):
                if rest[0] not in SUBCOMMANDS[name] and not rest[0].isupper():
                    wrong.append(f"unknown `dronectl {name} {rest[0]}`: {piece.strip()}")
                    continue
                argv = (name, rest[0]) if rest[0] in SUBCOMMANDS[name] else argv
            if name == "collect" and any(word.startswith("--vehicle") for word in rest):
                argv = (name, "--vehicle=sim-mavlink")  # the flown collection has options of its own
            known = set(OPTION.findall(help_text(argv))) | {"--help", "--debug"}
            wrong += [
                f"`dronectl {' '.join(argv)}` has no {option}: {piece.strip()}"
                for option in OPTION.findall(" ".join(rest))
                if option not in known
            ]
    return wrong


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(REPO)))
def test_docs_name_only_commands_and_options_that_exist(doc: Path) -> None:
    assert not wrong_names(doc), "\n".join(wrong_names(doc))


def test_the_check_sees_a_wrong_option_and_a_wrong_command(tmp_path: Path) -> None:
    doc = tmp_path / "doc.md"
    doc.write_text(
        "Run `dronectl fly --mission m.yaml --no-such-flag` or\n"
        "```bash\ndronectl benchmark-missions --n 10 \\\n    --seed 1 --nope  # a comment --fine\n"
        "dronectl fly-away\ndronectl bench nonsense\n```\n"
        "`dronectl fly --also-wrong`  PLACEHOLDER (another branch adds it)\n"
    )
    found = wrong_names(doc)
    said = " ".join(found)
    assert "has no --no-such-flag" in said and "has no --nope" in said
    assert "`dronectl fly-away`" in said and "`dronectl bench nonsense`" in said
    assert "--also-wrong" not in said and "--fine" not in said and "has no --seed" not in said
    assert len(found) == 4, found


LINK = re.compile(r"\]\(([^)\s]+)\)")


def slug(heading: str) -> str:
    """A heading's anchor as GitHub makes it: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def broken_links(doc: Path) -> list[str]:
    """Relative links in `doc` to a file that does not exist, or to a heading the file does not have."""
    broken = []
    for target in LINK.findall(doc.read_text()):
        if re.match(r"[a-z]+:", target):
            continue  # http:, https:, mailto:
        path, _, anchor = target.partition("#")
        file = (doc.parent / path).resolve() if path else doc
        if not file.exists():
            broken.append(f"{target}: no such file")
        elif anchor and file.suffix == ".md":
            headings = re.findall(r"^#+\s+(.+)$", file.read_text(), flags=re.M)
            if anchor not in {slug(h) for h in headings}:
                broken.append(f"{target}: no such heading")
    return broken


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(REPO)))
def test_docs_link_only_to_what_exists(doc: Path) -> None:
    assert not broken_links(doc), broken_links(doc)


def test_the_link_check_sees_a_missing_page_and_a_missing_heading(tmp_path: Path) -> None:
    (tmp_path / "other.md").write_text("# Other page\n\n## Pointing the camera at a drone\n")
    doc = tmp_path / "doc.md"
    doc.write_text(
        "[a](other.md#pointing-the-camera-at-a-drone) [b](other.md#nowhere) [c](gone.md) "
        "[d](https://example.com/x)\n"
    )
    assert broken_links(doc) == ["other.md#nowhere: no such heading", "gone.md: no such file"]
