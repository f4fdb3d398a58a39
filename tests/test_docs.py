"""The documentation holds together: every relative link in README.md, docs/*.md and
docs/decisions/*.md resolves (file and #anchor), every docs page can be reached from the README
or docs/index.md, and every `hopkinson …` command the pages quote parses with the real argument
parser (nothing is run).

A quoted command may be a synopsis: `[--opt V]` is read as given, `A|B` as its first
alternative (at a sub-command, each), `…` dropped (or, as an option's value, a placeholder), a
placeholder value (`N`, `P`, `HZ`) given a value its option's type accepts, and the command
ends at a shell operator (`| psql`, `&& next`, `> out.json`). A quote that names only a command
(`hopkinson campaign run`) must name one that exists; one with arguments must parse whole,
a missing positional argument filled in as prose leaves it out (`hopkinson identify --explain`).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import io
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest

from hopkinson.rig.cli.main import build_parser

REPO = Path(__file__).resolve().parents[1]
# docs/decisions/ holds the design's decision records (docs/architecture.md), one page each
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")),
         *sorted((REPO / "docs" / "decisions").glob("*.md"))]

FENCE = re.compile(r"^(```|~~~)(.*)$")
INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE_DEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s+<?(\S+?)>?(?:\s+\".*\")?\s*$")
HTML_LINK = re.compile(r"""<(?:a|img)\s[^>]*?(?:href|src)\s*=\s*["']([^"']+)["']""", re.I)
INLINE_CODE = re.compile(r"(`+)(.+?)\1")
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
COMMAND_START = re.compile(r"^(?:\$\s+)?(?:\S*/)?hopkinson\s+(?=[-a-z])")
PLACEHOLDER = re.compile(r"^[A-Z][A-Z0-9_]*(?:\.[a-z0-9]+)?$")
ELLIPSIS = ("…", "...")
SHELL_OPERATORS = {"|", "||", "&&", ";", "&"}


@dataclass(frozen=True)
class Quote:
    """One `hopkinson …` command quoted in a page."""

    page: Path
    line: int
    text: str

    def __str__(self) -> str:
        return f"{self.page.relative_to(REPO)}:{self.line}: {self.text}"


def _lines_outside_code(text: str) -> list[tuple[int, str, bool]]:
    """(line number, line, inside a fenced code block) for every line of a page."""
    rows, fenced = [], False
    for number, line in enumerate(text.splitlines(), start=1):
        if FENCE.match(line.strip()):
            fenced = not fenced
            rows.append((number, line, True))
            continue
        rows.append((number, line, fenced))
    return rows


def _without_inline_code(line: str) -> str:
    return INLINE_CODE.sub("", line)


def _links(page: Path) -> list[tuple[int, str]]:
    found = []
    for number, line, fenced in _lines_outside_code(page.read_text(encoding="utf-8")):
        if fenced:
            continue
        prose = _without_inline_code(line)
        for pattern in (INLINE_LINK, HTML_LINK):
            found += [(number, m.group(1)) for m in pattern.finditer(prose)]
        if m := REFERENCE_DEF.match(prose):
            found.append((number, m.group(1)))
    return found


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, markup and punctuation dropped, spaces to '-'."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link keeps its text
    text = re.sub(r"[`*_]", "", text).strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    anchors: set[str] = set()
    seen: dict[str, int] = {}
    for _number, line, fenced in _lines_outside_code(page.read_text(encoding="utf-8")):
        if fenced or not (m := HEADING.match(line)):
            continue
        slug = _slug(m.group(2))
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        anchors.add(slug if count == 0 else f"{slug}-{count}")
    return anchors


def _is_external(target: str) -> bool:
    return bool(re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I)) or target.startswith("//")


def _link_problem(page: Path, target: str) -> str | None:
    """Why a link of `page` does not resolve, or None."""
    if _is_external(target):
        return None
    path_part, _, anchor = target.partition("#")
    destination = (page.parent / path_part).resolve() if path_part else page
    if not destination.exists():
        return f"{target}: no such file"
    if REPO not in destination.parents and destination != REPO:
        return f"{target}: outside the repository"
    if anchor and destination.suffix == ".md" and anchor not in _anchors(destination):
        return f"{target}: no heading #{anchor} in {destination.relative_to(REPO)}"
    return None


def test_every_relative_link_resolves() -> None:
    problems = [f"{page.relative_to(REPO)}:{number}: {why}" for page in PAGES for number, target in _links(page)
                if (why := _link_problem(page, target))]
    assert not problems, "\n".join(problems)


def test_every_docs_page_is_reachable_from_the_readme_or_the_index() -> None:
    linked = set()
    for page in (REPO / "README.md", REPO / "docs" / "index.md"):
        for _number, target in _links(page):
            if not _is_external(target) and target.partition("#")[0]:
                linked.add((page.parent / target.partition("#")[0]).resolve())
    unreached = [p.relative_to(REPO) for p in PAGES[1:] if p.name != "index.md" and p.resolve() not in linked]
    assert not unreached, f"docs pages linked from neither README.md nor docs/index.md: {unreached}"


def test_every_docs_page_starts_with_who_it_is_for() -> None:
    """The title, then a paragraph that begins with whom the page is for ("For …" or "**For** …")."""
    missing = []
    for page in PAGES[1:]:
        lines = [line.strip() for line in page.read_text(encoding="utf-8").splitlines()]
        body = [line for line in lines[1:] if line]
        if not (lines and lines[0].startswith("# ") and body and re.match(r"^(\*\*)?For(\*\*)? ", body[0])):
            missing.append(str(page.relative_to(REPO)))
    assert not missing, f"pages that do not start with a title and whom they are for: {missing}"


def _quotes(page: Path) -> list[Quote]:
    """Every `hopkinson …` command in a page: inline code and the lines of code blocks (a line
    ending in a backslash continued by the next)."""
    quotes = []
    held: tuple[int, str] | None = None
    for number, line, fenced in _lines_outside_code(page.read_text(encoding="utf-8")):
        if fenced:
            if held is not None:
                number, line = held[0], held[1] + " " + line.strip()
                held = None
            if line.rstrip().endswith("\\"):
                held = (number, line.rstrip()[:-1])
                continue
            candidates = [line.strip()]
        else:
            candidates = [m.group(2).strip() for m in INLINE_CODE.finditer(line.replace("\\|", "|"))]
        for text in candidates:
            if COMMAND_START.match(text):
                quotes.append(Quote(page, number, text))
    return quotes


ALL_QUOTES = [quote for page in PAGES for quote in _quotes(page)]


def _words(text: str) -> list[str]:
    """The argv a quote stands for: comments, prompts and synopsis brackets removed."""
    text = COMMAND_START.sub("", text, count=1)
    text = re.sub(r"\s#\s.*$", "", text)  # a trailing comment
    text = re.sub(r"\[([^\[\]]*?)\s\|\s[^\[\]]*\]", r"\1", text)  # [--a | --b]: the first
    text = text.replace("[", " ").replace("]", " ")
    try:
        words = shlex.split(text)
    except ValueError:  # an unbalanced quote in prose
        words = text.split()
    for i, word in enumerate(words):  # the command ends at a shell operator: `| psql`, `&& next`, `> file`
        if word in SHELL_OPERATORS or word[:1] in "<>" or word[:2] in ("2>", "1>", "&>"):
            words = words[:i]
            break
    return [w if w in ELLIPSIS else w.removesuffix("…").removesuffix("...") for w in words]


@functools.cache
def _parser() -> argparse.ArgumentParser:
    return build_parser()


def _subparsers(parser: argparse.ArgumentParser) -> argparse._SubParsersAction | None:
    return next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)


def _command_paths(parser: argparse.ArgumentParser, words: list[str]) -> list[tuple[list[str], list[str]]]:
    """([sub-command words], [the rest]) for each alternative `a|b` at a sub-command."""
    sub = _subparsers(parser)
    if words and words[0] in ELLIPSIS:  # `hopkinson lab …`: any of its commands
        return [([], [])]
    if sub is None or not words or words[0].startswith("-"):
        return [([], words)]
    paths = []
    for name in words[0].split("|"):
        if name not in sub.choices:
            raise LookupError(f"no command {name!r} (known: {', '.join(sub.choices)})")
        paths += [([name, *head], rest) for head, rest in _command_paths(sub.choices[name], words[1:])]
    return paths


def _leaf(parser: argparse.ArgumentParser, path: list[str]) -> argparse.ArgumentParser:
    for name in path:
        sub = _subparsers(parser)
        assert sub is not None
        parser = sub.choices[name]
    return parser


def _value_for(action: argparse.Action, placeholder: str) -> str:
    """A value for a placeholder that the option's type and choices accept."""
    candidates = [*(str(c) for c in action.choices or ()), placeholder, "1", "0.5", "auto", "off"]
    for candidate in candidates:
        if action.choices and candidate not in map(str, action.choices):
            continue
        try:
            if callable(action.type):
                action.type(candidate)
        except (ValueError, TypeError, argparse.ArgumentTypeError):
            continue
        return candidate
    return placeholder


def _with_values(leaf: argparse.ArgumentParser, rest: list[str]) -> list[str]:
    """The argv with each option's placeholder value replaced by one its type accepts; `a|b` as a."""
    argv, previous = [], None
    for word in rest:
        option = leaf._option_string_actions.get(previous or "")
        if word in ELLIPSIS:  # "…": an option's value left out, or "and so on"
            if option is not None and option.nargs != 0:
                argv.append(_value_for(option, "X"))
            previous = None
            continue
        if option is not None and option.nargs != 0 and not word.startswith("-"):
            alternatives = word.split("|")
            word = next((a for a in alternatives if not PLACEHOLDER.match(a)), alternatives[0])
            if PLACEHOLDER.match(word):
                word = _value_for(option, word)
        elif not word.startswith("-"):
            word = word.split("|")[0]
        argv.append(word)
        previous = word if word.startswith("-") else None
    return argv


def _parse(argv: list[str]) -> str | None:
    """The parser's error for argv, or None (a --help or --version exit counts as parsed)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            _parser().parse_args(argv)
        except SystemExit as stop:
            return None if stop.code == 0 else err.getvalue().strip().splitlines()[-1]
    return None


def _missing_positionals(error: str) -> int:
    m = re.search(r"the following arguments are required: (.*)$", error)
    if not m or any(name.startswith("-") for name in m.group(1).split(", ")):
        return 0
    return len(m.group(1).split(", "))


def quote_problem(quote: Quote) -> str | None:
    """Why a quoted command does not parse, or None."""
    parser = _parser()
    try:
        paths = _command_paths(parser, _words(quote.text))
    except LookupError as exc:
        return str(exc)
    for path, rest in paths:
        if not rest:
            continue  # a command named in prose: it exists
        argv = [*path, *_with_values(_leaf(parser, path), rest)]
        error = _parse(argv)
        if error and (missing := _missing_positionals(error)):
            error = _parse([*argv, *["x"] * missing])
        if error:
            return f"{' '.join(argv)}: {error}"
    return None


def test_the_pages_quote_commands() -> None:
    """The check below has something to check: the README's tour and the commands page."""
    pages = {q.page.name for q in ALL_QUOTES}
    assert {"README.md", "commands.md", "method.md"} <= pages
    assert len(ALL_QUOTES) > 40


@pytest.mark.parametrize("quote", ALL_QUOTES, ids=str)
def test_every_quoted_command_parses(quote: Quote) -> None:
    assert quote_problem(quote) is None, f"{quote}\n{quote_problem(quote)}"


@pytest.mark.parametrize("text, wrong", [
    ("hopkinson identfy RECORD", "no command 'identfy'"),
    ("hopkinson identify RECORD --max-ordr 3", "unrecognized arguments: --max-ordr"),
    ("hopkinson identify RECORD --draws many", "invalid int value"),
    ("hopkinson shot --sim --projectile 7", "invalid choice"),
    ("hopkinson lab import|sertificate RUN", "no command 'sertificate'"),
    ("hopkinson shot --sim --yes --pressure-bar 2 --jsn > shot.json && next", "unrecognized arguments: --jsn"),
])
def test_a_command_that_no_longer_parses_is_named(text: str, wrong: str) -> None:
    problem = quote_problem(Quote(REPO / "README.md", 1, text))
    assert problem is not None and wrong in problem, problem


def test_a_broken_link_and_a_missing_anchor_are_named(tmp_path: Path) -> None:
    assert _link_problem(REPO / "README.md", "docs/no-such-page.md") == "docs/no-such-page.md: no such file"
    assert "no heading #no-such-heading" in (_link_problem(REPO / "README.md", "docs/method.md#no-such-heading") or "")
    assert _link_problem(REPO / "README.md", "docs/method.md#uncertainty") is None
    assert _slug("The bar's physics, shot planning & the `[bar]` table") == "the-bars-physics-shot-planning--the-bar-table"


def test_the_coverage_study_refuses_a_figure_file_it_cannot_write_before_it_starts(tmp_path: Path) -> None:
    """A wrong --out (the tables are printed, the file is the figure) is named at once, exit 2,
    not as a traceback after minutes of shots."""
    import subprocess
    import sys

    script = REPO / "docs" / "coverage_realistic.py"
    done = subprocess.run([sys.executable, str(script), "--shots", "1", "--out", str(tmp_path / "study.md")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert "study.md" in done.stderr and ".png" in done.stderr
    assert "Traceback" not in done.stderr and not done.stdout
    assert not (tmp_path / "study.md").exists()
