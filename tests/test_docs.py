"""The docs stand alone and say what is true of the tree.

- No file under ``docs/`` or ``src/`` (text files), nor ``README.md`` or ``CHANGELOG.md``,
  cites a file outside the repository, a numbered work log or an issue number: a reader could
  not look any of them up. Facts name their public source instead (the paper and its section,
  a peer's public repository, or a file of this repository).
- Every package under ``src/pioneer/`` has its folder under ``tests/`` (the tests mirror src).
- Every ``pioneer`` command the README, ``docs/`` and the docstrings' command lines show
  exists: ``pioneer PATH --help`` exits 0 and its usage names that path.
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "pioneer"
TEXT_SUFFIXES = {".py", ".md", ".json", ".toml", ".txt", ".cfg", ".ini", ".yaml", ".yml"}

# What a reader cannot look up. Case-sensitive where the word is a file name in capitals.
FORBIDDEN = {
    "a specification file outside the repository": re.compile(r"\bSPEC\b"),
    "a references file outside the repository": re.compile(r"\bREFERENCES\b"),
    "a style guide outside the repository": re.compile(r"\bSTYLE\.md\b"),
    "a shared folder outside the repository": re.compile(r"(?<![\w.-])\.\./shared/"),
    "a work log": re.compile(r"(?i)\bwork[ -]?logs?\b"),
    "a numbered session": re.compile(r"(?i)\bsessions?[ -]#?\d+"),
    "an issue number": re.compile(r"(?i)\bissues?[ -]#?\d+"),
    "a tracker reference (#N)": re.compile(r"(?<![\w&#/])#\d{1,5}\b"),
}


def _text_files() -> Iterator[Path]:
    yield ROOT / "README.md"
    yield ROOT / "CHANGELOG.md"
    for top in (ROOT / "docs", SRC):
        for p in sorted(top.rglob("*")):
            if p.is_file() and p.suffix in TEXT_SUFFIXES and "__pycache__" not in p.parts:
                yield p


def test_docs_cite_nothing_a_reader_cannot_look_up():
    found = []
    for p in _text_files():
        for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
            for what, pattern in FORBIDDEN.items():
                if m := pattern.search(line):
                    found.append(f"{p.relative_to(ROOT)}:{n}: {what}: {m.group(0)!r}")
    assert not found, "\n".join(found)


@pytest.mark.parametrize(
    ("line", "bad"),
    [
        ("see SPEC 1.4", True),
        ("(REFERENCES.md)", True),
        ("measured in session 12", True),
        ("Session-14 figures", True),
        ("issue 19, item 1", True),
        ("fixed in #42", True),
        ("the work log says", True),
        ("`../shared/notes.md`", True),
        ("spec.py holds the scenario config", False),
        ("one `session.run` per decision", False),
        ("a recording session: many episodes", False),
        ("colour #1f77b4 and `a[#]`", False),
        ("# Heading", False),
    ],
)
def test_the_patterns_catch_what_they_should(line, bad):
    assert any(p.search(line) for p in FORBIDDEN.values()) == bad


def _packages(root: Path) -> list[Path]:
    """Every package below ``root`` (a folder with ``__init__.py``), relative to it."""
    return sorted(
        p.parent.relative_to(root)
        for p in root.rglob("__init__.py")
        if p.parent != root and "data" not in p.parent.relative_to(root).parts
    )


def test_every_package_has_its_test_folder():
    packages = _packages(SRC)
    assert Path("baselines") in packages and Path("sim/scenarios") in packages
    missing = [str(p) for p in packages if not (ROOT / "tests" / p).is_dir()]
    assert not missing, f"no tests/<package>/ for: {missing}"
    empty = [str(p) for p in packages if not any((ROOT / "tests" / p).glob("test_*.py"))]
    assert not empty, f"no test_*.py in tests/<package>/ for: {empty}"


# --------------------------------------------------------------------------- commands shown


FENCE = re.compile(r"^(\s*)```+\s*([\w+-]*)\s*$")
SHELLS = {"", "bash", "sh", "shell", "console", "zsh"}
OPERATORS = {"|", "||", "&&", ";", ">", ">>", "2>", "2>&1", "&"}
LAUNCHERS = {"time", "-v", "/usr/bin/time", "nohup", "exec", "&&", ";", "|"}


def _fenced_lines(text: str) -> tuple[list[str], str]:
    """Shell lines of the fenced blocks (continuations joined) and the text outside them."""
    shell: list[str] = []
    prose: list[str] = []
    lang: str | None = None
    for line in text.splitlines():
        if m := FENCE.match(line):
            lang = m.group(2).lower() if lang is None else None
            continue
        if lang is None:
            prose.append(line)
        elif lang in SHELLS:
            if shell and shell[-1].endswith("\\"):
                shell[-1] = shell[-1][:-1] + " " + line.strip()
            else:
                shell.append(line.strip())
    return shell, "\n".join(prose)


def _argv(command: str) -> list[str] | None:
    """The words after ``pioneer`` in a shell line, or None when it runs no ``pioneer``."""
    try:
        words = shlex.split(command.removeprefix("$ "), comments=True)
    except ValueError:  # an unbalanced quote in prose
        words = command.split()
    for i, w in enumerate(words):
        if (w == "pioneer" or w.endswith("/bin/pioneer")) and (i == 0 or words[i - 1] in LAUNCHERS):
            rest = words[i + 1 :]
            cut = next((k for k, t in enumerate(rest) if t in OPERATORS), len(rest))
            return rest[:cut]
    return None


def _expand(argv: list[str]) -> list[list[str]]:
    """Optional ``[…]`` parts dropped; ``a|b`` alternatives of a word each taken."""
    kept = [w for w in argv if not (w.startswith("[") or w.endswith("]"))]
    out: list[list[str]] = [[]]
    for w in kept:
        alts = w.split("|") if "|" in w and "=" not in w and "{" not in w else [w]
        out = [[*o, a] for o in out for a in alts if a]
    return out


def _shown_commands() -> dict[tuple[str, ...], str]:
    """Each distinct (global options, leading words) of the commands shown → where first."""
    from pioneer.cli._app import _split

    shown: dict[tuple[str, ...], str] = {}

    def add(argv: list[str] | None, where: str) -> None:
        for a in _expand(argv) if argv is not None else []:
            head = _split(a)[0]  # the global options, read as the command line reads them
            i = len(head)  # its files, if any, gathered last behind one --scenarios
            if "--scenarios" in head:
                head = [*head[: head.index("--scenarios")], "--scenarios", "FILE"]
            words = []
            for w in a[i:]:
                if w.startswith("-") or w in {"…", "..."}:
                    break
                words.append(w)
            if words and words[0].isupper():  # a synopsis (pioneer COMMAND …)
                continue
            shown.setdefault((*head, "|", *words), where)

    docs = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    for p in docs:
        shell, prose = _fenced_lines(p.read_text(encoding="utf-8"))
        where = str(p.relative_to(ROOT))
        for line in shell:
            add(_argv(line), where)
        for span in re.findall(r"(?<!`)`(pioneer\s[^`]+)`(?!`)", prose):
            add(_argv(" ".join(span.split())), where)
    for p in sorted(SRC.rglob("*.py")):
        text = p.read_text(encoding="utf-8")
        where = str(p.relative_to(ROOT))
        for line in re.findall(r"(?m)^\s*(?:\$ )?(pioneer\s.*)$", text):
            add(_argv(line), where)
        for span in re.findall(r"``(pioneer\s[^`]+)``", text):
            add(_argv(" ".join(span.split())), where)
    return shown


SHOWN = _shown_commands()


def test_commands_are_found_in_the_docs():
    paths = {key[key.index("|") + 1 :][:2] for key in SHOWN}
    assert ("reproduce",) in {p[:1] for p in paths}
    assert ("train", "crowdnav++") in paths and ("sample-layouts",) in {p[:1] for p in paths}
    assert any(key[:2] == ("--scenarios", "FILE") for key in SHOWN)


def _usage(out: str) -> list[str]:
    """The words of the usage block that ``--help`` prints (until the first blank line)."""
    block = out.split("usage:", 1)[1].split("\n\n", 1)[0]
    return block.split()


def _positionals(usage: list[str]) -> int:
    """How many positional arguments a usage line lists (outside brackets, not an option's
    metavar)."""
    depth, count, after_option = 0, 0, False
    for w in usage:
        opened = depth > 0 or w.startswith("[")
        depth += w.count("[") - w.count("]")
        if opened or w.startswith("{"):
            after_option = False
            continue
        if w.startswith("-"):
            after_option = True
            continue
        if not after_option and w not in {"…", "..."}:
            count += 1
        after_option = False
    return count


@pytest.mark.parametrize("key", sorted(SHOWN), ids=lambda k: " ".join(w for w in k if w != "|"))
def test_every_command_shown_exists(key, capsys):
    """``pioneer [GLOBAL] WORDS --help`` exits 0, its usage names the command, and any word
    after the command is one of its positional arguments (``pioneer scenarios sample`` is not:
    ``scenarios`` takes none)."""
    from pioneer.cli import main

    bar = key.index("|")
    head, words = list(key[:bar]), list(key[bar + 1 :])
    with pytest.raises(SystemExit) as exc:
        main([*head, *words, "--help"])
    out = capsys.readouterr().out
    shown = " ".join(["pioneer", *head, *words])
    assert int(exc.value.code or 0) == 0, f"{SHOWN[key]}: {shown}: {out}"
    usage = _usage(out)
    assert usage[0] == "pioneer"
    n = 0
    while n < len(words) and 1 + n < len(usage) and usage[1 + n] == words[n]:
        n += 1
    prog, extra = usage[: 1 + n], words[n:]
    assert n > 0 or not words, f"{SHOWN[key]}: no command {words[0]!r}"
    if extra:  # words after the command: its positional arguments, or a command that is not
        with pytest.raises(SystemExit):
            main([*head, *prog[1:], "--help"])  # the usage without them lists them
        positionals = _positionals(_usage(capsys.readouterr().out)[len(prog) :])
        assert len(extra) <= positionals, (
            f"{SHOWN[key]}: {' '.join(['pioneer', *words])}: {extra} is not a command of "
            f"{' '.join(prog)}"
        )
    if head:  # the global options shown exist
        with pytest.raises(SystemExit):
            main(["--help"])
        top = capsys.readouterr().out
        assert all(opt in top for opt in head if opt.startswith("-"))
