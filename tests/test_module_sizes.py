"""Modules stay small enough to read in one sitting: none in ``src/pioneer`` is over
:data:`LIMIT` lines unless docs/architecture.md lists it, with its reason, in the table of
"Size limits and their exceptions" — the one list, read here."""

from __future__ import annotations

import re
from pathlib import Path

import pioneer

LIMIT = 500  # lines of a module
FUNCTION_LIMIT = 80  # lines of a function
SRC = Path(pioneer.__file__).parent
DOC = Path(__file__).resolve().parents[1] / "docs" / "architecture.md"
SECTION = "## Size limits and their exceptions"


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def listed_exceptions(text: str) -> dict[str, str]:
    """``{module path under src/pioneer: reason}`` from the section's table rows
    (``| `sim/kernel_simd.py` | why |``)."""
    return _section_rows(text, r"[^`]+\.py")


def test_the_exceptions_table_parses():
    rows = listed_exceptions(
        f"{SECTION}\n\n| module | why |\n|---|---|\n| `a/b.py` | one kernel |\n\n## Next\n"
        "| `c.py` | elsewhere |\n"
    )
    assert rows == {"a/b.py": "one kernel"}


def _section_rows(text: str, key: str) -> dict[str, str]:
    """``{key: reason}`` of the section's table rows whose first cell matches ``key``."""
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    return dict(re.findall(rf"^\| `({key})` \| (.+?) \|$", section, flags=re.MULTILINE))


def _check_listed(over: dict[str, int], listed: dict[str, str], what: str, limit: int) -> None:
    """Every ``over`` item is listed with its reason, and every listed one is over."""
    unlisted = {k: n for k, n in over.items() if k not in listed}
    assert not unlisted, (
        f"over {limit} lines: {unlisted}; split the {what}, or list it with its reason in "
        f"docs/architecture.md ({SECTION[3:]})"
    )
    stale = sorted(k for k in listed if k not in over)
    assert not stale, f"listed in docs/architecture.md but not over {limit} lines: {stale}"
    assert all(len(why) > 20 for why in listed.values()), "every exception gives its reason"


def test_no_module_is_over_the_limit_unless_listed_with_its_reason():
    over = {
        p.relative_to(SRC).as_posix(): _lines(p)
        for p in sorted(SRC.rglob("*.py"))
        if _lines(p) > LIMIT
    }
    _check_listed(over, listed_exceptions(DOC.read_text(encoding="utf-8")), "module", LIMIT)


def listed_functions(text: str) -> dict[str, str]:
    """``{"path.py::name": reason}`` from the section's function rows."""
    return _section_rows(text, r"[^`]+\.py::\w+")


def test_no_function_is_over_its_limit_unless_listed_with_its_reason():
    import ast

    over = {}
    for p in sorted(SRC.rglob("*.py")):
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                n = (node.end_lineno or node.lineno) - node.lineno + 1
                if n > FUNCTION_LIMIT:
                    over[f"{p.relative_to(SRC).as_posix()}::{node.name}"] = n
    listed = listed_functions(DOC.read_text(encoding="utf-8"))
    _check_listed(over, listed, "function", FUNCTION_LIMIT)
