"""The one lazy policy registry: every controller by name, resolved by entry-point string.

Like Gymnasium's environment registry, an entry names its factory as ``"module:attribute"``;
nothing is imported until a policy is built, so every name resolves without prior imports
(and the evaluation parent never loads torch). Each entry may also name a *check* — a light
function ``check(scenario, kwargs)`` that raises before a run starts when a part the policy
would load is missing (shipped demos, weights, students).

Third-party packages add policies through the ``pioneer.policies`` entry-point group::

    [project.entry-points."pioneer.policies"]
    my-planner = "my_package.planner:make_planner"

The value may also point at a :class:`PolicyEntry` (to give fixed keyword arguments, a check
or the extra that provides it).

:func:`resolve_policy` says what a policy is made of in a scenario — every parameter with the
value it gets and the content hash of every file it loads — so that an evaluation's records
name what made them.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.metadata
import inspect
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from pioneer.envs.policy import Policy
from pioneer.errors import ConfigError, expect
from pioneer.io import file_record
from pioneer.parameters import check_parameters

__all__ = [
    "ENTRY_POINT_GROUP",
    "FILE_PARAMETERS",
    "PolicyEntry",
    "build_policy",
    "check_parts",
    "check_policy_kwargs",
    "check_policy_name",
    "make_policy",
    "policy_entry",
    "policy_factory",
    "policy_names",
    "policy_paths",
    "register_policy",
    "resolve_policy",
]

ENTRY_POINT_GROUP = "pioneer.policies"
# Parameters that name a file the factory loads ("{scenario}" in them is filled in).
FILE_PARAMETERS = ("checkpoint", "model", "reward", "weights")


@dataclasses.dataclass(frozen=True)
class PolicyEntry:
    """A registered policy: its factory (``"module:attribute"`` or a callable), the keyword
    arguments fixed for this name, an optional light check of its parts, the pip extra whose
    packages the factory imports, and an optional function naming the files it loads when a
    path parameter is unset (:mod:`pioneer.control.policy_files`)."""

    name: str
    entry_point: str | Callable[..., Policy]
    kwargs: tuple[tuple[str, Any], ...] = ()
    check: str | None = None  # "module:function(scenario, kwargs)"
    extra: str = ""  # e.g. "learn" (torch)
    summary: str = ""
    files: str | None = None  # "module:function(scenario, params) -> {name: Path}"

    def target(self) -> Callable[..., Policy]:
        """The factory itself, without the fixed keyword arguments (imports its module); its
        signature's annotations type the policy's parameters."""
        return self.entry_point if callable(self.entry_point) else self._load(self.entry_point)

    def factory(self) -> Callable[..., Policy]:
        """The factory with this entry's fixed keyword arguments (imports its module)."""
        fn = self.target()
        if not self.kwargs:
            return fn
        fixed = dict(self.kwargs)

        def bound(**kw: Any) -> Policy:
            return fn(**{**fixed, **kw})

        bound.__signature__ = inspect.signature(fn)  # type: ignore[attr-defined]
        return bound

    def _load(self, target: str) -> Any:
        module, _, attr = target.partition(":")
        try:
            obj: Any = importlib.import_module(module)
        except ImportError as exc:
            fix = f"pip install 'pioneer-nav[{self.extra}]'" if self.extra else "install it"
            raise ConfigError(
                expect(f"policy {self.name!r}", f"{target} importable", str(exc), fix)
            ) from exc
        for part in attr.split("."):
            obj = getattr(obj, part)
        return obj


def _builtin(
    key: str,
    target: str,
    summary: str,
    *,
    check: str | None = None,
    extra: str = "",
    files: str | None = None,
    **kw: Any,
) -> PolicyEntry:
    return PolicyEntry(key, target, tuple(sorted(kw.items())), check, extra, summary, files)


_TEACHER = "pioneer.control.teacher:make_teacher"
_OWN = "pioneer.control.policy_files"
_TEACHER_PARTS = {"check": f"{_OWN}:check_teacher", "files": f"{_OWN}:teacher_files"}
_STUDENT_PARTS = {"check": f"{_OWN}:check_student", "files": f"{_OWN}:student_files"}
_CROWDNAV_PARTS = {"check": f"{_OWN}:check_crowdnav", "files": f"{_OWN}:crowdnav_files"}
_SB3_PARTS = {"check": f"{_OWN}:check_sb3", "files": f"{_OWN}:sb3_files"}
# The paper's teacher (§IV-A.2): no soft margins, and a stop when no command is feasible.
_PAPER_TEACHER: dict[str, Any] = {
    "human_margin": 0.0,
    "wall_margin": 0.0,
    "fallback": "stop",
    "patience": 0.0,
}
_BUILTINS = (
    _builtin(
        "teacher",
        _TEACHER,
        "our lookahead teacher: the paper's with soft margins and the evade fallback",
        **_TEACHER_PARTS,
    ),
    _builtin(
        "teacher-paper",
        _TEACHER,
        "the paper's lookahead teacher (§IV-A.2): no soft margins, stops when no command is "
        "feasible",
        **_TEACHER_PARTS,
        **_PAPER_TEACHER,
        name="teacher-paper",
    ),
    _builtin(
        "teacher-paper-no-density",
        _TEACHER,
        "the paper's teacher without R_den (Table II)",
        **_PAPER_TEACHER,
        density=False,
        name="teacher-paper-no-density",
    ),
    _builtin(
        "teacher-paper-no-goal",
        _TEACHER,
        "the paper's teacher without R_goal (Table II)",
        **_TEACHER_PARTS,
        **_PAPER_TEACHER,
        goal=False,
        name="teacher-paper-no-goal",
    ),
    _builtin(
        "teacher-paper-no-obstacle",
        _TEACHER,
        "the paper's teacher without R_obs (Table II)",
        **_TEACHER_PARTS,
        **_PAPER_TEACHER,
        obstacle=False,
        name="teacher-paper-no-obstacle",
    ),
    _builtin(
        "teacher-patient",
        _TEACHER,
        "our teacher that drops its learned term once it makes no progress (Patience)",
        **_TEACHER_PARTS,
        patient=True,
        name="teacher-patient",
    ),
    _builtin(
        "teacher-paper-evade",
        _TEACHER,
        "the paper's teacher with our evade fallback (no soft margins; calibrate's driver)",
        **_TEACHER_PARTS,
        human_margin=0.0,
        wall_margin=0.0,
        patience=0.0,
        name="teacher-paper-evade",
    ),
    _builtin(
        "teacher-no-density",
        _TEACHER,
        "our teacher (soft margins, evade fallback) without R_den (Table II)",
        density=False,
        name="teacher-no-density",
    ),
    _builtin(
        "teacher-no-goal",
        _TEACHER,
        "our teacher (soft margins, evade fallback) without R_goal (Table II)",
        **_TEACHER_PARTS,
        goal=False,
        name="teacher-no-goal",
    ),
    _builtin(
        "teacher-no-obstacle",
        _TEACHER,
        "our teacher (soft margins, evade fallback) without R_obs (Table II)",
        **_TEACHER_PARTS,
        obstacle=False,
        name="teacher-no-obstacle",
    ),
    _builtin("goal", "pioneer.baselines.classic:GoalPolicy", "drive straight to the goal"),
    _builtin("dwa", "pioneer.baselines.classic:DWAPolicy", "dynamic window approach"),
    _builtin("sfm", "pioneer.baselines.classic:SocialForceRobotPolicy", "social-force robot"),
    _builtin("cvar-bf", "pioneer.baselines.cvar_bf:make_cvar_bf", "adaptive CVaR barrier QP"),
    _builtin(
        "crowdnav++",
        "pioneer.baselines.crowdnav.policy:make_crowdnav_policy",
        "CrowdNav++ GRU-attention policy, pure PPO (the original's recipe)",
        **_CROWDNAV_PARTS,
        extra="learn",
    ),
    _builtin(
        "crowdnav++-il",
        "pioneer.baselines.crowdnav.policy:make_crowdnav_policy",
        "CrowdNav++ warm-started by imitation of sfm, then PPO",
        **_CROWDNAV_PARTS,
        extra="learn",
        variant="il",
        name="crowdnav++-il",
    ),
    _builtin(
        "crowdnav++-il-teacher",
        "pioneer.baselines.crowdnav.policy:make_crowdnav_policy",
        "CrowdNav++ warm-started by imitation of our teacher, then PPO on the CrowdNav++ reward "
        "without its intrusion term",
        **_CROWDNAV_PARTS,
        extra="learn",
        variant="il-teacher",
        name="crowdnav++-il-teacher",
    ),
    _builtin(
        "sb3-ppo",
        "pioneer.baselines.sb3:make_sb3_policy",
        "Stable-Baselines3 PPO on the LiDAR observation, SB3's defaults (beyond the paper)",
        **_SB3_PARTS,
        extra="sb3",
    ),
    _builtin(
        "student-mdn",
        "pioneer.learn.policy:make_student_policy",
        "DAgger MDN student",
        **_STUDENT_PARTS,
        extra="learn",
        kind="mdn",
        name="student-mdn",
    ),
    _builtin(
        "student-mdn-paper",
        "pioneer.learn.policy:make_student_policy",
        "DAgger MDN student, the paper's recipe (§V-B.2: teacher without margins)",
        **_STUDENT_PARTS,
        extra="learn",
        kind="mdn",
        recipe="paper",
        name="student-mdn-paper",
    ),
    _builtin(
        "student-mlp",
        "pioneer.learn.policy:make_student_policy",
        "DAgger MLP student",
        **_STUDENT_PARTS,
        extra="learn",
        kind="mlp",
        name="student-mlp",
    ),
    _builtin(
        "student-general",
        "pioneer.learn.policy:make_student_policy",
        "one MDN student for many elevator layouts, DAgger then PPO (beyond the paper)",
        **_STUDENT_PARTS,
        extra="learn",
        kind="mdn",
        general=True,
        name="student-general",
    ),
    _builtin(
        "student-onnx",
        "pioneer.deploy.runtime:make_onnx_student_policy",
        "exported student on ONNX Runtime",
        extra="deploy",
    ),
    _builtin(
        "student-shield",
        "pioneer.learn.shield:make_shield_policy",
        "MDN student with an uncertainty shield",
        check=f"{_OWN}:check_shield",
        files=f"{_OWN}:shield_files",
        extra="learn",
    ),
)

_ENTRIES: dict[str, PolicyEntry] = {e.name: e for e in _BUILTINS}
_PLUGINS_LOADED = False
_UNRESOLVED_PLUGINS: set[str] = set()  # entry points whose target may be a PolicyEntry


def _load_plugins() -> None:
    """Add the ``pioneer.policies`` entry points of installed distributions (once)."""
    global _PLUGINS_LOADED
    if _PLUGINS_LOADED:
        return
    _PLUGINS_LOADED = True
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in _ENTRIES:
            continue  # a plugin never shadows a registered name
        _ENTRIES[ep.name] = PolicyEntry(ep.name, ep.value, summary=f"from {ep.value}")
        _UNRESOLVED_PLUGINS.add(ep.name)


def register_policy(
    name: str,
    factory: str | Callable[..., Policy],
    *,
    check: str | None = None,
    extra: str = "",
    summary: str = "",
    **kwargs: Any,
) -> PolicyEntry:
    """Make a policy constructible by name: ``factory`` is ``"module:attribute"`` (imported on
    first use) or a callable; ``kwargs`` are fixed for this name."""
    entry = PolicyEntry(name, factory, tuple(sorted(kwargs.items())), check, extra, summary)
    _ENTRIES[name] = entry
    return entry


def policy_names() -> list[str]:
    """Every registered policy name (built-in and plugins)."""
    _load_plugins()
    return sorted(_ENTRIES)


def policy_entry(name: str) -> PolicyEntry:
    """The entry of ``name``, or :class:`ConfigError` listing the known names."""
    _load_plugins()
    entry = _ENTRIES.get(name)
    if entry is None:
        raise ConfigError(
            expect("policy", f"one of {policy_names()}", name, "pick a listed policy")
        )
    # A plugin's entry point may name a PolicyEntry instead of a factory.
    if name in _UNRESOLVED_PLUGINS and isinstance(entry.entry_point, str):
        _UNRESOLVED_PLUGINS.discard(name)
        obj = entry._load(entry.entry_point)
        if isinstance(obj, PolicyEntry):
            entry = dataclasses.replace(obj, name=name)
            _ENTRIES[name] = entry
    return entry


def check_policy_name(name: str) -> None:
    """Raise :class:`ConfigError` unless ``name`` is registered (imports nothing)."""
    _load_plugins()
    if name not in _ENTRIES:
        policy_entry(name)


def policy_factory(name: str) -> Callable[..., Policy]:
    """The factory registered under ``name`` (imports its module)."""
    return policy_entry(name).factory()


def check_policy_kwargs(name: str, kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """``kwargs`` checked against the parameters the factory of ``name`` declares — their
    names, types and ``Annotated`` ranges, declared once on the factory's signature — and
    returned typed (imports the factory: torch for the students). Raises :class:`ConfigError`
    naming the parameter, what it takes and the fix; so does a required parameter (one without
    a default) that neither ``kwargs`` nor the entry gives."""
    entry = policy_entry(name)
    return check_parameters(f"policy {name}", entry.target(), dict(kwargs), dict(entry.kwargs))


def check_parts(name: str, scenario: str, kwargs: Mapping[str, Any]) -> None:
    """Run the entry's light check of the parts it would load for ``scenario`` (no torch)."""
    entry = policy_entry(name)
    if entry.check:
        entry._load(entry.check)(scenario, {**dict(entry.kwargs), **kwargs})


def build_policy(name: str, scenario: str | None = None, **kwargs: Any) -> Policy:
    """Construct ``name``, passing ``scenario`` only to factories that take it (the teacher
    needs the scenario to pick its reward; the go-to-goal controller does not). With a
    scenario, the entry's check of its parts runs first (:func:`check_parts`): a reward model
    that does not fit the scenario is refused here, not halfway through an episode."""
    factory = policy_factory(name)
    if scenario is not None:
        check_parts(name, scenario, kwargs)
        if "scenario" in inspect.signature(factory).parameters:
            kwargs["scenario"] = scenario
    return factory(**kwargs)


def _resolved(
    name: str, scenario: str, kwargs: Mapping[str, Any]
) -> tuple[dict[str, Any], dict[str, Path]]:
    """Every parameter of ``name``'s factory with the value it gets, and the files it loads."""
    entry = policy_entry(name)
    target = entry.target()
    fixed = dict(entry.kwargs)
    given = check_parameters(f"policy {name}", target, dict(kwargs), fixed)
    params: dict[str, Any] = {
        p.name: p.default
        for p in inspect.signature(target).parameters.values()
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
        and p.name != "scenario"
        and p.default is not p.empty
    }
    params.update(fixed)
    params.update(given)
    files: dict[str, Path] = {}
    for key in FILE_PARAMETERS:
        if isinstance(params.get(key), str | Path):
            params[key] = str(params[key]).replace("{scenario}", scenario)
            files[key] = Path(params[key])
    if entry.files:
        files.update(entry._load(entry.files)(scenario, params))
    return params, files


def policy_paths(name: str, scenario: str, kwargs: Mapping[str, Any]) -> list[Path]:
    """The files policy ``name`` with ``kwargs`` loads in ``scenario`` (not read: e.g. to
    refuse an output onto one of them)."""
    return list(_resolved(name, scenario, kwargs)[1].values())


def resolve_policy(name: str, scenario: str, kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """What policy ``name`` with ``kwargs`` is made of in ``scenario``, as plain JSON data:
    ``{"policy": name, "params": {…}, "files": {key: {"path", "sha256"}}}`` — every parameter
    of its factory with the value it gets (given, fixed by the entry, or its default; a path's
    ``{scenario}`` filled in) and the content hash of every file it loads: the given paths of
    :data:`FILE_PARAMETERS` and the shipped files the entry falls back on. Imports the factory
    (torch for the students)."""
    params, files = _resolved(name, scenario, kwargs)
    return {
        "policy": name,
        "params": {k: _plain(v) for k, v in sorted(params.items())},
        "files": {k: file_record(p) for k, p in sorted(files.items())},
    }


def _plain(value: Any) -> Any:
    """``value`` as JSON data (a config as its fields, a tuple as a list, anything else that
    JSON cannot hold as its repr)."""
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return _plain(dataclasses.asdict(value))
    return repr(value)


def make_policy(name: str, **kwargs: Any) -> Policy:
    """Construct a registered policy by name."""
    return policy_factory(name)(**kwargs)
