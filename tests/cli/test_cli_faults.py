"""Every ``pioneer`` command through the same output faults.

One table of commands, one of faults. Each pair must end in one ``pioneer: error:`` line
with exit code 2 that names the path. The thing at the path stays as it was (a FIFO stays a
FIFO, ``/dev/full`` a device), and nothing is left half-written. The fault classes are:
under a file, the wrong kind of path (a folder where a file goes and the reverse), a FIFO, a
character device, a place the user may not write, and a full disk (a file-size limit).
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from pioneer.cli import main
from pioneer.data import DEMOS_DIR, STUDENTS_DIR
from pioneer.errors import DataError
from pioneer.io import check_regular_target, output_dir_kind
from pioneer_testutils import file_tree, one_error_line

STATIC_DEMOS = str(DEMOS_DIR / "static.npz")
STUDENT = str(STUDENTS_DIR / "hr-rl-compact-mdn.safetensors")
RUN = "run --scenario static --policy goal --seed 0"

# name: (the command with OUT for the output path, what the path must be, cheap enough to run
# to the end)
COMMANDS: dict[str, tuple[str, str, bool]] = {
    "run --png": (f"{RUN} --png OUT", "file", True),
    "run --gif": (f"{RUN} --gif OUT", "file", True),
    "scenarios --png-dir": ("scenarios --png-dir OUT", "folder", True),
    "demos generate": (
        "demos generate --scenario static --out OUT --positive 1 --negative 1",
        "file",
        True,
    ),
    "reward fit": (f"reward fit --demos {STATIC_DEMOS} --out OUT", "file", True),
    "export": (f"export --model {STUDENT} --out OUT", "file", True),
    "replay": ("replay --bag no.bag --model no.onnx --out OUT --goal 1 0", "file", False),
    "eval": (
        "eval --policy goal --scenario static --seeds 1 --workers 1 --out OUT",
        "folder",
        True,
    ),
    "reproduce": ("reproduce --profile smoke --out OUT", "folder", False),
    "calibrate": ("calibrate --episodes 1 --out OUT", "folder", False),
    "distill": ("distill --scenario static --out OUT", "folder", False),
    "train crowdnav++": ("train crowdnav++ --out OUT", "folder", False),
    "study static": ("study static --out OUT", "folder", False),
    "study blind-sector": ("study blind-sector --out OUT", "folder", False),
}


def argv(name: str, out: str | Path) -> list[str]:
    """The command ``name`` writing to ``out``."""
    return [str(out) if word == "OUT" else word for word in COMMANDS[name][0].split()]


def _one_error_line(capsys: pytest.CaptureFixture[str], code: int, *needles: str) -> str:
    return one_error_line(capsys.readouterr().err, code, *needles)


def _faulty_path(fault: str, kind: str, tmp: Path) -> tuple[str, str]:
    """(the output path for ``fault``, a word the error line must contain)."""
    (tmp / "a-file").write_text("keep me\n")
    (tmp / "a-folder").mkdir()
    os.mkfifo(tmp / "a-fifo")
    if fault == "under a file":
        return str(tmp / "a-file" / "out"), "Not a directory"
    if fault == "wrong kind":
        return (
            (str(tmp / "a-folder"), "a folder")
            if kind == "file"
            else (
                str(tmp / "a-file"),
                "a regular file",
            )
        )
    if fault == "fifo":
        return str(tmp / "a-fifo"), "FIFO"
    raise AssertionError(fault)


@pytest.mark.parametrize("fault", ["under a file", "wrong kind", "fifo"])
@pytest.mark.parametrize("name", list(COMMANDS))
def test_bad_output_path_is_one_line_and_leaves_everything(
    name, fault, tmp_path, capsys, monkeypatch
):
    kind = COMMANDS[name][1]
    monkeypatch.chdir(tmp_path)  # a command past the check would write here, not in the repo
    out, needle = _faulty_path(fault, kind, tmp_path)
    before = file_tree(tmp_path)
    code = main(argv(name, out))
    _one_error_line(capsys, code, needle, "fix:")
    assert file_tree(tmp_path) == before


@pytest.mark.parametrize("name", list(COMMANDS))
def test_character_device_is_refused_untouched(name, tmp_path, capsys, monkeypatch):
    device = Path("/dev/full")
    if not device.is_char_device():
        pytest.skip("no /dev/full here")
    # The guard first, in-process, so that a broken guard fails here and never reaches the
    # command (which, run as root, would replace the device with a regular file).
    with pytest.raises(DataError, match="character device"):
        check_regular_target(device)
    with pytest.raises(DataError, match="character device"):
        output_dir_kind(device)
    monkeypatch.chdir(tmp_path)  # a command past the check would write here, not in the repo
    rdev = device.stat().st_rdev
    code = main(argv(name, device))
    _one_error_line(capsys, code, "/dev/full", "character device", "fix:")
    assert device.is_char_device() and device.stat().st_rdev == rdev
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", list(COMMANDS))
def test_unwritable_place_is_one_line(name, tmp_path, capsys, monkeypatch):
    place = Path("/sys")  # not writable for anyone, root included (sysfs)
    if not place.is_dir():
        pytest.skip("no /sys here")
    monkeypatch.chdir(tmp_path)  # a command past the check would write here, not in the repo
    out = place / "pioneer-test" / ("out.png" if COMMANDS[name][1] == "file" else "dir")
    if name == "replay":  # its input is checked before its output is written
        pytest.skip("replay refuses the missing bag first; its writer is the atomic one")
    code = main(argv(name, out))
    _one_error_line(capsys, code, "/sys/", "expected a path that can be read or written", "fix:")
    assert not (place / "pioneer-test").exists()


FULL = [name for name, (_, _, cheap) in COMMANDS.items() if cheap]


@pytest.mark.parametrize("name", FULL)
def test_full_disk_is_one_line_and_leaves_no_partial_file(name, tmp_path):
    """A file-size limit of 1 KiB (``ulimit -f 1``) stands in for a full disk: the writer gets
    EFBIG, as it would get ENOSPC. A first, unlimited run fills numba's cache, whose writes
    would otherwise hit the limit first."""
    kind = COMMANDS[name][1]
    cmd = [sys.executable, "-c", "import sys; from pioneer.cli import main; sys.exit(main())"]
    warm = subprocess.run(
        [*cmd, *argv(name, tmp_path / "warm" / ("w.png" if kind == "file" else "w"))],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert warm.returncode == 0, warm.stderr[-2000:]
    target = tmp_path / "full" / ("out.png" if kind == "file" else "out")
    (tmp_path / "full").mkdir()

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (1024, resource.RLIM_INFINITY))

    proc = subprocess.run(
        [*cmd, *argv(name, target)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
        preexec_fn=limit,
    )
    one_error_line(proc.stderr, proc.returncode, "File too large", str(target.parent))
    if kind == "file":
        assert list((tmp_path / "full").iterdir()) == []  # no temporary file, no torn output
    else:  # a folder may exist; every file in it is whole (the run resumes from it)
        for p in target.rglob("*"):
            assert p.is_dir() or p.stat().st_size <= 1024
        for p in target.rglob("*.jsonl"):
            assert p.read_text() == "" or p.read_text().endswith("\n")


def test_missing_optional_dependency_is_one_line_naming_the_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "onnx", None)  # as if `pip install onnx` never ran
    code = main(argv("export", tmp_path / "s.onnx"))
    _one_error_line(capsys, code, "module onnx", "pip install 'pioneer-nav[learn]'")
    assert list(tmp_path.iterdir()) == []


def test_missing_sb3_names_its_extra(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)
    out = tmp_path / "sb3"
    code = main(["train", "sb3-ppo", "--scenario", "static", "--steps", "64", "--out", str(out)])
    _one_error_line(capsys, code, "module stable_baselines3", "pip install 'pioneer-nav[sb3]'")
    assert not out.exists()


def test_every_extra_named_in_errors_is_one_of_the_packages_extras():
    """:data:`pioneer.errors.EXTRAS` names extras that ``pyproject.toml`` declares."""
    import tomllib

    from pioneer.errors import EXTRAS

    root = Path(__file__).resolve().parents[2]
    declared = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    assert set(EXTRAS.values()) <= set(declared["optional-dependencies"])


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (
            "eval --policy goal --scenario static --workers 0 --out OUT",
            "--workers: expected an integer >= 1",
        ),
        ("run --scenario static --seed -1", "--seed: expected an integer >= 0"),
        ("distill --scenario static --workers -2 --out OUT", "--workers"),
    ],
)
def test_option_bounds_are_checked_before_any_work(args, needle, tmp_path, capsys):
    out = tmp_path / "out"
    code = main([str(out) if w == "OUT" else w for w in args.split()])
    _one_error_line(capsys, code, needle, "fix:")
    assert not out.exists()


def test_partial_writes_of_a_killed_process_are_removed(tmp_path):
    from pioneer.io import atomic_path, remove_partial_writes

    keep = tmp_path / "r" / "ep-001.npz"
    keep.parent.mkdir()
    keep.write_bytes(b"whole")
    (tmp_path / "r" / ".hidden-user-file").write_text("mine")
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "r" / "ep-002.npz") as tmp:
        stray = tmp.with_name(tmp.name)  # what a SIGKILL would leave: the temporary file
        tmp.write_bytes(b"half")
        os.link(tmp, stray.with_name(stray.name.replace("ep-002", "ep-003")))
        raise RuntimeError("killed")
    assert remove_partial_writes(tmp_path) == 1
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == [".hidden-user-file", "ep-001.npz"]
    assert remove_partial_writes(tmp_path / "missing") == 0
