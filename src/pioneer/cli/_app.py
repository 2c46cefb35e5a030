"""The command tree of ``pioneer``, parsed with tyro, and :func:`main`.

A command's options are a frozen dataclass in the module of its group (``evaluation``,
``scenarios``, ``learning``, ``demos``, ``deploy``, ``reward``) with a ``run`` method. Those
modules import what the defaults are read from (torch for ``distill``, the simulator for
``eval``), so only the chosen command's module is imported: the command line is parsed in
two steps, both by tyro. The tree (``pioneer [--scenarios FILE] COMMAND``, with ``--help``
listing the commands) is parsed with a placeholder per command, then the command's own
options, as ``pioneer eval …`` (its ``--help`` lists its defaults). ``pioneer --version``
alone prints the version.
"""

from __future__ import annotations

import contextlib
import dataclasses
import difflib
import gc
import importlib
import os
import sys
import typing
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Annotated, Any, NoReturn, Protocol, cast

import tyro

from pioneer.cli._files import check_outputs
from pioneer.cli._parse import one_line, parse, refuse
from pioneer.config import check_option_bounds
from pioneer.errors import PioneerError, expect, missing_dependency_line, os_error_line
from pioneer.interrupt import Interrupted, handle_signals
from pioneer.io import naming_path

__all__ = ["main"]


class Command(Protocol):
    """A parsed command: its options, and ``run`` to carry it out (returns the exit code)."""

    def run(self) -> int:
        """Do the work; a :class:`~pioneer.errors.PioneerError` becomes one line, exit 2."""
        ...


@dataclasses.dataclass(frozen=True)
class _Leaf:
    target: str  # "module:Class" in pioneer.cli
    help: str

    def load(self) -> type[Command]:
        """The options class (importing its module: what its defaults are read from)."""
        module, name = self.target.split(":")
        return cast(type[Command], getattr(importlib.import_module(f"pioneer.cli.{module}"), name))


@dataclasses.dataclass(frozen=True)
class _Group:
    help: str
    children: dict[str, _Leaf | _Group]


_TREE = _Group(
    "PioneeR social navigation toolkit (pioneer --version: its version)",
    {
        "run": _Leaf("evaluation:Run", "run one episode of a policy; optionally write a GIF/PNG"),
        "scenarios": _Leaf(
            "scenarios:Scenarios", "list the scenarios (with --scenarios files); draw them"
        ),
        "eval": _Leaf(
            "evaluation:Eval", "evaluate policies: N seeds × M trials, parallel, resumable"
        ),
        "summarize": _Leaf(
            "evaluation:Summarize", "re-summarise a run folder from its records (runs nothing)"
        ),
        "reproduce": _Leaf("evaluation:Reproduce", "the paper's tables and figures (the main job)"),
        "sample-layouts": _Leaf(
            "scenarios:SampleLayouts", "draw valid layouts of the randomised elevator world"
        ),
        "calibrate": _Leaf(
            "scenarios:Calibrate", "world statistics beside the paper's evidence (validation seeds)"
        ),
        "distill": _Leaf(
            "learning:Distill", "DAgger: distil the teacher into a LiDAR-only student"
        ),
        "finetune": _Leaf(
            "learning:Finetune", "fine-tune a DAgger student with PPO (resumes an existing --out)"
        ),
        "export": _Leaf("deploy:Export", "student checkpoint → ONNX, with a parity check"),
        "replay": _Leaf("deploy:Replay", "ROS bag LaserScans → student commands CSV (no ROS)"),
        "train": _Group(
            "train an RL baseline",
            {
                "crowdnav++": _Leaf(
                    "learning:TrainCrowdNav", "CrowdNav++ with PPO (resumes an existing --out)"
                ),
                "sb3-ppo": _Leaf(
                    "learning:TrainSb3", "Stable-Baselines3 PPO on the Gymnasium environment"
                ),
            },
        ),
        "demos": _Group(
            "demonstration datasets",
            {
                "generate": _Leaf("demos:DemosGenerate", "scripted demonstrations (γ = +1 and −1)"),
                "show": _Leaf("demos:DemosShow", "summary of a dataset file"),
            },
        ),
        "teleop": _Leaf("demos:Teleop", "drive with the keyboard and record labelled demos"),
        "reward": _Group(
            "the learned density reward",
            {
                "fit": _Leaf("reward:RewardFit", "fit the density reward on a dataset"),
                "show": _Leaf("reward:RewardShow", "summary of a fitted model"),
            },
        ),
        "study": _Group(
            "paper studies",
            {
                "static": _Leaf("reward:StudyStatic", "the synthetic static study (paper Fig. 3)"),
                "blind-sector": _Leaf(
                    "learning:StudyBlindSector",
                    "students with a narrower scanner under each fill rule of unseen directions",
                ),
            },
        ),
    },
)

_SCENARIOS_HELP = (
    "register the scenario variants of a JSON file (format pioneer.scenarios/1, see "
    "docs/simulator.md) for the command; same as listing it in PIONEER_SCENARIOS; several "
    "files follow one --scenarios (--scenarios A B), or the flag repeats (--scenarios A "
    "--scenarios B)"
)


def _tree_type(name: str, group: _Group) -> Any:
    """A dataclass whose ``command`` field is the union of ``group``'s children (tyro's
    subcommands); a command is a placeholder without options (parsed on its own)."""
    options = []
    for child_name, child in group.children.items():
        child_type = (
            _tree_type(child_name, child)
            if isinstance(child, _Group)
            else dataclasses.make_dataclass(child_name, [], frozen=True)
        )
        sub = tyro.conf.subcommand(child_name, description=child.help, prefix_name=False)
        options.append(Annotated[child_type, sub])
    # "| None", suppressed: a group of one command is still a choice (tyro needs a union).
    union: Any = typing.Union
    required = Annotated[union[(*options, None)], tyro.conf.DisallowNone]
    fields: list[Any] = [("command", required)]
    if group is _TREE:
        files = Annotated[
            tuple[str, ...],
            tyro.conf.arg(
                metavar="FILE", help=_SCENARIOS_HELP, help_behavior_hint="(default: none)"
            ),
        ]
        fields.append(("scenarios", files, dataclasses.field(default=())))
    return dataclasses.make_dataclass(name, fields, frozen=True)


def _split(argv: Sequence[str]) -> tuple[list[str], list[str], _Leaf | _Group, list[str]]:
    """``argv`` as (global options, command names, the node they name, the rest: the
    command's options). The files of every ``--scenarios`` (each followed by one or more,
    up to the next option or command name) are gathered behind one ``--scenarios``."""
    i, head, files, given = 0, [], [], False
    while i < len(argv) and argv[i].startswith("-"):
        if argv[i] != "--scenarios":
            head.append(argv[i])
            i += 1
            continue
        given, i = True, i + 1
        while i < len(argv) and not argv[i].startswith("-") and argv[i] not in _TREE.children:
            files.append(argv[i])
            i += 1
    if given and not files:
        refuse(expect("pioneer --scenarios", "one or more FILE", None, "name a scenario file"))
    if given:
        head += ["--scenarios", *files]
    start, node = i, cast(_Leaf | _Group, _TREE)
    while isinstance(node, _Group) and i < len(argv) and argv[i] in node.children:
        node = node.children[argv[i]]
        i += 1
    return head, list(argv[start:i]), node, list(argv[i:])


def _parse(argv: Sequence[str]) -> tuple[Command, tuple[str, ...]]:
    """The chosen command's options and the ``--scenarios`` files; exits 0 after ``--help``
    and 2 (one line on stderr) on a bad command line."""
    head, path, node, rest = _split(argv)
    prog = " ".join(["pioneer", *path])
    tree = _tree_type("pioneer", _TREE)
    if isinstance(node, _Group):  # no command yet: help, or a missing or an unknown one
        if rest and not rest[0].startswith("-"):
            _unknown_command(rest[0], node, prog)
        parse(tree, argv, "pioneer", _TREE.help, label=prog)
        refuse(expect(prog, "a command", None, f"see {prog} --help"))  # tyro refused already
    parsed = parse(tree, [*head, *path], "pioneer", _TREE.help)
    return parse(node.load(), rest, prog), parsed.scenarios


def _unknown_command(word: str, group: _Group, prog: str) -> NoReturn:
    names = list(group.children)
    near = difflib.get_close_matches(word, names, n=1)
    fix = f"did you mean {near[0]}? (see {prog} --help)" if near else f"see {prog} --help"
    refuse(expect(prog, f"a command, one of {', '.join(names)}", word, fix))


def _single_threaded_blas() -> None:
    """The matrices here are small; BLAS threads only fight the simulation and the workers
    for the cores (a teacher decision takes 3x longer with OpenBLAS's default threads)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")


def _register_scenario_files(files: Sequence[str]) -> None:
    """Add ``--scenarios`` files to ``PIONEER_SCENARIOS``, which spawned worker processes
    inherit, and load them here once (a bad file fails before any work). Without files the
    simulator is not imported, so robot-side commands (``replay``) stay free of numba."""
    if files:
        from pioneer.sim.scenarios import SCENARIOS_ENV, load_env_scenarios

        paths = [str(Path(f).resolve()) for f in files]
        old = os.environ.get(SCENARIOS_ENV)
        os.environ[SCENARIOS_ENV] = os.pathsep.join([*filter(None, [old]), *paths])
        try:
            load_env_scenarios()
        except BaseException:  # a refused file is not kept for what runs next
            if old is None:
                del os.environ[SCENARIOS_ENV]
            else:
                os.environ[SCENARIOS_ENV] = old
            raise


class _NamedStdout:
    """``sys.stdout`` whose write errors name it (a full disk behind ``> out.txt``, ``>
    /dev/full``): the one error line then says where the failed write went."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        """Write ``text``; an :class:`OSError` names standard output."""
        with naming_path("standard output"):
            return int(self._stream.write(text))

    def flush(self) -> None:
        """Flush; an :class:`OSError` names standard output."""
        with naming_path("standard output"):
            self._stream.flush()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


@contextlib.contextmanager
def _named_stdout() -> Iterator[None]:
    """Run the block with :class:`_NamedStdout` as ``sys.stdout`` and flush it at the end
    (inside, so a failed flush is reported like any write)."""
    stream = sys.stdout
    sys.stdout = cast(Any, _NamedStdout(stream))
    try:
        yield
        sys.stdout.flush()
    finally:
        sys.stdout = stream


@handle_signals()
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pioneer`` console script: parse, run, and turn any
    :class:`~pioneer.errors.PioneerError` into one line on stderr and exit code 2, and
    SIGINT / SIGTERM into one line naming what was kept and the command that resumes, exit
    code 130 / 143 (:mod:`pioneer.interrupt`)."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args == ["--version"]:
        from pioneer import __version__

        print(f"pioneer {__version__}")
        return 0
    try:
        command, scenario_files = _parse(args)
        _single_threaded_blas()
        _register_scenario_files(scenario_files)
        check_option_bounds(command)  # --workers >= 1, --seed >= 0 …
        check_outputs(command, scenario_files)
        with _named_stdout():
            return int(command.run())
    except PioneerError as exc:
        return _refused(str(exc))
    except Interrupted as exc:
        print(f"pioneer: {exc.message(['pioneer', *args])}", file=sys.stderr)
        if argv is None:  # the process ends next: skip the collector's sweep at exit (≈ 1 s)
            gc.freeze()
        return exc.exit_code
    except BrokenPipeError:  # `pioneer run --frames | head`: the reader left; stop quietly
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + 13  # as if killed by SIGPIPE, the shell's convention
    except OSError as exc:  # reading or writing a file: unwritable, full, wrong kind of path
        return _refused(os_error_line(exc))
    except ModuleNotFoundError as exc:  # an optional dependency that is not installed
        if (exc.name or "").split(".")[0] == "pioneer":
            raise
        return _refused(missing_dependency_line(exc))


def _refused(line: str) -> int:
    """The one error path: one line on stderr (line breaks in a message folded), exit code 2."""
    print(f"pioneer: error: {one_line(line)}", file=sys.stderr)
    return 2
