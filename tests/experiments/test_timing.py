"""The time ``pioneer reproduce`` announces: stored episode times scaled by this machine's
probe and by the workers the run really uses (no absolute timing is asserted here)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from pioneer.experiments import timing
from pioneer.experiments.reproduce_plan import (
    BASELINES,
    CLASSIC,
    PAPER_TEACHERS,
    SHIELD,
    STUDENTS,
    TEACHERS,
)
from pioneer.experiments.timing import (
    EpisodeTimes,
    announcement,
    estimate,
    parallel_speed,
)

TIMES = EpisodeTimes(
    episode_s={"teacher": 0.3, "goal": 0.01},
    default_episode_s=0.1,
    overhead_s=12.0,
    cold_jit_s=30.0,
    measured="2030-01-01",
    machine="A CPU (zen: avx2), 2 CPUs, Linux",
    probe_s=0.002,
)


def _estimate(workers: int = 2, **kw):
    """The estimate of 1,000 episodes per row on a fake machine (its speed, CPUs and load)."""
    args = {"speed": 1.0, "cpus": 2, "load": 1.0, "times": TIMES, **kw}
    return estimate(["teacher"], ["goal"], 1000, workers, False, **args)


def test_on_the_stored_machine_two_workers_take_the_stored_time():
    est = _estimate()
    assert est.paper_s == pytest.approx(0.3 * 1000 / 2)
    assert est.extra_s == pytest.approx(0.01 * 1000 / 2)
    assert est.fixed_s == pytest.approx(12.0)
    assert (est.cores, est.busy) == (2, 0.0)


@pytest.mark.parametrize("speed", [0.5, 1.0, 2.0, 3.3])
def test_the_stored_times_scale_with_the_probed_speed(speed):
    """A machine ``speed`` times as fast (the stored probe ÷ this one's) takes 1/speed of
    every part of the time."""
    base, est = _estimate(), _estimate(speed=speed)
    for part in ("paper_s", "extra_s", "fixed_s"):
        assert getattr(est, part) == pytest.approx(getattr(base, part) / speed)


def test_the_speed_is_the_probe_ratio(monkeypatch):
    monkeypatch.setattr(timing, "probe", lambda: (0.004, 1.0))  # half the stored machine's
    est = estimate(["teacher"], [], 1000, 2, False, cpus=2, load=1.0, times=TIMES)
    assert est.speed == pytest.approx(0.5)
    assert est.paper_s == pytest.approx(0.3 * 1000 / 2 / 0.5)
    unprobed = EpisodeTimes({"teacher": 0.3}, 0.1, 0.0, 0.0, "2030-01-01", "x", probe_s=None)
    assert estimate(["teacher"], [], 10, 2, False, cpus=2, load=1.0, times=unprobed).speed == 1


def test_more_workers_than_cpus_promise_no_speed_up():
    two = _estimate(workers=2)
    for workers in (3, 8, 64):
        est = _estimate(workers=workers)
        assert est.cores == 2
        assert est.paper_s == pytest.approx(two.paper_s)
    assert _estimate(workers=1).paper_s == pytest.approx(2 * two.paper_s, rel=0.02)


def test_sixteen_cpus_run_seven_times_as_fast_as_two():
    """The paper profile on 16 cores (16 workers, 1,420 % CPU) ran ≈ 7× as fast as on 2."""
    assert parallel_speed(2) == pytest.approx(2.0)
    assert parallel_speed(16) / parallel_speed(2) == pytest.approx(7.0)
    two = _estimate(workers=2, cpus=16)
    sixteen = _estimate(workers=16, cpus=16)
    assert two.paper_s / sixteen.paper_s == pytest.approx(7.0)
    assert parallel_speed(8) < 4 * parallel_speed(2)
    speeds = [parallel_speed(n) for n in range(1, 65)]
    assert speeds == sorted(speeds)  # another worker never slows the run


def test_other_work_on_the_cpus_slows_the_run():
    idle = _estimate(load=1.0)  # this process alone
    one_busy = _estimate(load=2.0)  # one CPU kept busy by another process
    assert one_busy.busy == pytest.approx(1.0)
    # 3 running processes on 2 CPUs: our 2 workers get 2 × 2/3 of a CPU
    assert one_busy.paper_s == pytest.approx(idle.paper_s * 3 / 2)
    # 8 others beside our 2 workers: a fifth of the 2 CPUs each
    assert _estimate(load=9.0).paper_s == pytest.approx(idle.paper_s * 10 / 2)
    assert _estimate(load=0.2).paper_s == pytest.approx(idle.paper_s)
    # one worker on 2 CPUs beside one other process: a CPU of its own
    assert _estimate(workers=1, load=2.0).paper_s == pytest.approx(_estimate(workers=1).paper_s)
    # the start-up and the report run in one process: a CPU of its own beside one other
    assert one_busy.fixed_s == pytest.approx(idle.fixed_s)
    assert _estimate(load=5.0).fixed_s == pytest.approx(idle.fixed_s * 5 / 2)


def test_a_probe_that_got_part_of_a_cpu_counts_the_others(monkeypatch):
    """A probe with half a CPU on 2 CPUs: 3 other processes; the 2 workers get 2/5 each."""
    monkeypatch.setattr(timing, "probe", lambda: (0.002, 0.5))
    est = estimate(["teacher"], [], 1000, 2, False, cpus=2, times=TIMES)
    assert est.busy == pytest.approx(3.0)
    assert est.paper_s == pytest.approx(_estimate().paper_s * 5 / 2)
    monkeypatch.setattr(timing, "probe", lambda: (0.002, 1.0))  # a whole CPU: the load average
    monkeypatch.setattr(timing.os, "getloadavg", lambda: (9.0, 9.0, 9.0))
    est = estimate(["teacher"], [], 1000, 2, False, cpus=2, times=TIMES)
    assert est.busy == pytest.approx(1.0)  # at most cpus − 1 beside a probe with a whole CPU


def test_a_cold_numba_cache_adds_the_compile_scaled_by_speed():
    warm = estimate(["goal"], [], 10, 2, False, speed=2.0, cpus=2, load=1.0, times=TIMES)
    cold = estimate(["goal"], [], 10, 2, True, speed=2.0, cpus=2, load=1.0, times=TIMES)
    assert cold.fixed_s - warm.fixed_s == pytest.approx(30.0 / 2.0)


@pytest.mark.parametrize("busy", [0.0, 1.7])
def test_the_announcement_is_one_line_under_300_characters(monkeypatch, busy):
    monkeypatch.setattr(timing, "episode_times", lambda: TIMES)
    est = timing.Estimate(601.0, 1234.5, 45.0, 64, 2, busy, 0.4321)
    line = announcement("paper", 123_456, 12_345, est)
    assert "\n" not in line and len(line) < 300
    assert line.startswith("pioneer reproduce --profile paper: 123,456 episodes (12,345 done)")
    assert "expected ≈ 31 min (paper's rows 10, others 21, start-up and report 1)" in line
    assert "with 64 worker(s) on 2 CPU(s)" in line
    assert (", ≈ 1.7 other busy processes" in line) == (busy > 0)
    assert line.endswith("; CPU speed 0.43× A CPU (zen)'s")
    short = announcement("quick", 960, 0, timing.Estimate(30.0, 20.0, 15.0, 2, 2, 0.0, 1.0))
    assert "expected ≈ 1.1 min (paper's rows 0.5, others 0.3" in short


def test_the_announcement_stays_short_with_any_machine_and_size(monkeypatch):
    long_name = "Intel(R) Xeon(R) Platinum 8375C CPU @ 2.90GHz (icelake-server: avx), 16 CPUs"
    monkeypatch.setattr(timing, "episode_times", lambda: dataclasses_replace(long_name))
    est = timing.Estimate(6e5, 6e5, 1e4, 1024, 1024, 123.4, 12.34)
    line = announcement("paper", 12_345_678, 12_345_677, est)
    assert len(line) < 300 and "…'s" in line


def dataclasses_replace(machine: str) -> EpisodeTimes:
    """:data:`TIMES` measured on ``machine``."""
    import dataclasses

    return dataclasses.replace(TIMES, machine=machine)


def test_the_probe_is_short_and_positive():
    t = timing.probe_seconds(rounds=3)
    assert 0 < t < 1.0  # one round of a few ms; no speed is asserted


def test_the_announced_machine_is_named_without_its_feature_list():
    def named(machine: str) -> str:
        return EpisodeTimes({}, 0.1, 0.0, 0.0, "2026-01-01", machine).machine_short()

    assert named("AMD EPYC (znver4: sse4.2+avx+avx2), 2 CPUs, Linux-6") == "AMD EPYC (znver4)"
    assert named("Intel Xeon, 2 CPUs") == "Intel Xeon"
    assert named("") == "unknown"


def test_the_shipped_episode_times_cover_every_row_of_the_run():
    from pioneer.experiments.timing import episode_times

    times = episode_times()
    rows = (*PAPER_TEACHERS, *TEACHERS, *BASELINES, *CLASSIC, *STUDENTS, SHIELD)
    assert set(rows) <= set(times.episode_s)
    assert all(s > 0 for s in times.episode_s.values())
    assert times.measured and times.machine  # a measurement names its date and machine
    assert times.probe_s  # and the machine's speed, which other machines are scaled by


def test_episode_times_round_trip_and_refuse_bad_files(tmp_path):
    from pioneer.errors import DataError
    from pioneer.experiments.timing import episode_times, load_episode_times

    p = tmp_path / "times.json"
    p.write_text(json.dumps(episode_times().to_dict()))
    assert load_episode_times(p) == episode_times()
    bad = {**episode_times().to_dict(), "overhead_s": -1}
    p.write_text(json.dumps(bad))
    with pytest.raises(DataError, match="overhead_s"):
        load_episode_times(p)
    p.write_text(json.dumps({"format": "something/1"}))
    with pytest.raises(DataError, match="format"):
        load_episode_times(p)
    with pytest.raises(DataError, match="readable JSON"):
        load_episode_times(tmp_path / "absent.json")


def test_the_benchmark_script_updates_the_rows_it_measured(monkeypatch):
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2]))  # the repository
    from benchmarks import episode_times as bench

    from pioneer.experiments.timing import episode_times

    old = episode_times()
    records = [
        {"policy": "goal", "wall_time_s": 0.2},
        {"policy": "goal", "wall_time_s": 0.4},
        {"policy": "my-policy", "wall_time_s": 1.0},
    ]
    new = bench.updated(old, records, "2030-01-02", "a machine", scale=2.0)
    assert new.of("goal") == pytest.approx(0.15) and new.of("my-policy") == pytest.approx(0.5)
    assert new.of("teacher") == old.of("teacher")  # not in the run: kept
    assert new.measured == "2030-01-02" and new.machine == "a machine"
    assert "divided by 2" in new.source
    assert any("cvar-bf" in n and old.measured in n for n in new.notes)  # kept rows named
    assert new.probe_s == old.probe_s  # no probe given: the old one stays
    probed = bench.updated(old, records, "2030-01-02", "a machine", probe_s=0.0123)
    assert probed.probe_s == 0.0123  # the machine's speed is stored with its times
    busy = [{"policy": "teacher", "wall_time_s": 3 * old.of("teacher")}]
    assert bench.relative_scale(busy, old, "teacher") == pytest.approx(3.0)


def test_rows_scaled_to_the_file_keep_its_machine_date_and_probe(monkeypatch, tmp_path):
    # --relative-to: the new rows are carried to the file's machine, so the file's probe (its
    # machine's speed) must stay; a plain run stores this machine's probe with its times
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2]))  # the repository
    from benchmarks import episode_times as bench

    from pioneer.experiments.timing import episode_times

    old = episode_times()
    out = tmp_path / "times.json"
    out.write_text(json.dumps(old.to_dict()))
    run = tmp_path / "run"
    (run / "eval").mkdir(parents=True)
    (run / "eval" / bench.EPISODES_FILE).write_text("")
    busy = [
        {"policy": "teacher", "wall_time_s": 2 * old.of("teacher")},
        {"policy": "my-row", "wall_time_s": 1.0},
    ]
    monkeypatch.setattr(bench, "read_records", lambda path: busy)
    monkeypatch.setattr(bench, "probe_seconds", lambda: 99.0)
    argv = [str(run), "--output", str(out), "--rows", "my-row"]
    assert bench.main([*argv, "--relative-to", "teacher"]) == 0
    new = bench.load_episode_times(out)
    assert new.of("my-row") == pytest.approx(0.5)  # halved: the run was twice as slow
    assert (new.probe_s, new.measured, new.machine) == (old.probe_s, old.measured, old.machine)
    assert bench.main(argv) == 0  # a run on this machine: its probe is stored
    assert bench.load_episode_times(out).probe_s == 99.0


def test_the_jit_cache_is_found_where_numba_keeps_it(tmp_path, monkeypatch):
    from numba.core import config

    from pioneer.experiments.timing import jit_cache_warm

    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "numba"))
    assert not jit_cache_warm()
    index = tmp_path / "numba" / "work_src_pioneer_sim" / "kernel.step_kernel-39.py311.nbi"
    index.parent.mkdir(parents=True)
    index.write_bytes(b"")
    assert not jit_cache_warm()  # the teacher's rollout kernel is compiled on its own
    (index.parent / "kernel_simd.trajectory_kernel_lanes-75.py311.nbi").write_bytes(b"")
    assert jit_cache_warm()
