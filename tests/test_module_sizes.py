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
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `([^`]+\.py)` \| (.+?) \|$", section, flags=re.MULTILINE)
    return dict(rows)


def test_the_exceptions_table_parses():
    rows = listed_exceptions(
        f"{SECTION}\n\n| module | why |\n|---|---|\n| `a/b.py` | one kernel |\n\n## Next\n"
        "| `c.py` | elsewhere |\n"
    )
    assert rows == {"a/b.py": "one kernel"}


def test_no_module_is_over_the_limit_unless_listed_with_its_reason():
    listed = listed_exceptions(DOC.read_text(encoding="utf-8"))
    over = {
        p.relative_to(SRC).as_posix(): _lines(p)
        for p in sorted(SRC.rglob("*.py"))
        if _lines(p) > LIMIT
    }
    unlisted = {m: n for m, n in over.items() if m not in listed}
    assert not unlisted, (
        f"over {LIMIT} lines: {unlisted}; split the module, or list it with its reason in "
        f"docs/architecture.md ({SECTION[3:]})"
    )
    stale = sorted(m for m in listed if m not in over)
    assert not stale, f"listed in docs/architecture.md but not over {LIMIT} lines: {stale}"
    assert all(len(why) > 20 for why in listed.values()), "every exception gives its reason"


def listed_functions(text: str) -> dict[str, str]:
    """``{"path.py::name": reason}`` from the section's function rows."""
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `([^`]+\.py::\w+)` \| (.+?) \|$", section, flags=re.MULTILINE)
    return dict(rows)


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
    unlisted = {f: n for f, n in over.items() if f not in listed}
    assert not unlisted, (
        f"over {FUNCTION_LIMIT} lines: {unlisted}; split the function, or list it with its "
        f"reason in docs/architecture.md ({SECTION[3:]})"
    )
    stale = sorted(f for f in listed if f not in over)
    assert not stale, f"listed but not over {FUNCTION_LIMIT} lines: {stale}"
    assert all(len(why) > 20 for why in listed.values()), "every exception gives its reason"
