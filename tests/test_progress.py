"""Progress bars: redrawn on a terminal, a few whole lines in a log (CI, a file, nohup)."""

from __future__ import annotations

import io

import pytest

from pioneer import progress
from pioneer.progress import LineWriter, progress_bar


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_line_writer_turns_redraws_into_lines():
    out = io.StringIO()
    w = LineWriter(out)
    w.write("\rfirst   ")
    w.write("\rsecond")
    w.write("\n")
    w.write("\r\r")
    assert out.getvalue() == "first\nsecond\n"


def test_a_log_gets_a_line_at_the_start_and_the_end_of_a_fast_run():
    out = io.StringIO()
    with progress_bar(total=1000, desc="episodes", unit="ep", file=out) as bar:
        for _ in range(1000):
            bar.update(1)
    text = out.getvalue()
    lines = text.splitlines()
    assert "\r" not in text
    assert 2 <= len(lines) <= 3  # LOG_EVERY_S has not passed: no line in between
    assert lines[-1].startswith("episodes: 100%") and "1000/1000" in lines[-1]
    assert all(len(x) < 300 for x in lines)


def test_a_log_gets_a_line_every_tenth_when_time_allows(monkeypatch):
    monkeypatch.setattr(progress, "LOG_EVERY_S", 0.0)
    out = io.StringIO()
    for _ in progress_bar(range(200), desc="steps", unit="step", file=out):
        pass
    lines = out.getvalue().splitlines()
    assert 10 <= len(lines) <= 12  # start, every 10 %, end
    assert [x.split("%")[0].split()[-1] for x in lines[:3]] == ["0", "10", "20"]


def test_a_terminal_gets_an_ordinary_redrawn_bar():
    out = Terminal()
    with progress_bar(total=50, desc="t", unit="x", file=out, mininterval=0) as bar:
        for _ in range(50):
            bar.update(1)
    assert out.getvalue().count("\r") > 10


@pytest.mark.parametrize("stream", [io.StringIO(), Terminal()])
def test_a_disabled_bar_writes_nothing(stream):
    with progress_bar(total=5, desc="quiet", unit="x", enabled=False, file=stream) as bar:
        bar.update(5)
    assert stream.getvalue() == ""
