"""No module over 600 lines without a reason stated at its top (issue 43 item 5, the developers'
guide: small modules with one job). A longer .py file in a package folder, tests/, benchmarks/
or docs/ needs a line in its module docstring starting with REASON, e.g. "Longer than 600 lines
because the protocol's 40 registers are one table." A module that grows past the limit is split
by subject instead (module fixtures shared through tests/shared_results.py so none is computed
twice)."""

from __future__ import annotations

import ast
from pathlib import Path

from tests.test_structure import PACKAGES, REPO

MAX_LINES = 600
REASON = "Longer than 600 lines because"
FOLDERS = (*PACKAGES, "tests", "benchmarks", "docs")


def lines_over_without_reason(path: Path) -> int | None:
    """The line count of `path` if it exceeds MAX_LINES and its module docstring states no
    reason (no line starting with REASON), else None."""
    text = path.read_text(encoding="utf-8")
    count = len(text.splitlines())
    if count <= MAX_LINES:
        return None
    docstring = ast.get_docstring(ast.parse(text, filename=str(path))) or ""
    if any(line.strip().startswith(REASON) for line in docstring.splitlines()):
        return None
    return count


def test_no_module_is_over_600_lines_without_a_stated_reason() -> None:
    modules = [path for folder in FOLDERS for path in sorted((REPO / folder).rglob("*.py"))
               if "__pycache__" not in path.parts]
    assert len(modules) > 300  # the folders were found
    too_long = {str(path.relative_to(REPO)): count for path in modules
                if (count := lines_over_without_reason(path)) is not None}
    assert too_long == {}, f"split these by subject, or state why at their top ({REASON} …)"


def test_the_rule_counts_lines_and_reads_the_reason_from_the_module_docstring(tmp_path: Path) -> None:
    body = "x = 1\n" * (MAX_LINES - 1)
    at_limit = tmp_path / "at_limit.py"
    at_limit.write_text('"""A module."""\n' + body, encoding="utf-8")
    assert lines_over_without_reason(at_limit) is None
    over = tmp_path / "over.py"
    over.write_text('"""A module."""\n' + body + "x = 2\n", encoding="utf-8")
    assert lines_over_without_reason(over) == MAX_LINES + 1
    stated = tmp_path / "stated.py"
    stated.write_text(f'"""A module.\n\n{REASON} its table is one piece.\n"""\n' + body, encoding="utf-8")
    assert lines_over_without_reason(stated) is None
    elsewhere = tmp_path / "elsewhere.py"  # the words in a comment, or mid-line, are no stated reason
    elsewhere.write_text(f'"""A module, not {REASON} anything."""\n# {REASON} a comment\n' + body, encoding="utf-8")
    assert lines_over_without_reason(elsewhere) == MAX_LINES + 1
