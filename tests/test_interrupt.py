"""``pioneer.interrupt``: SIGINT and SIGTERM as :class:`Interrupted`, held until the end of a
deferred block, ignored once stopping, and the one line naming what was kept."""

from __future__ import annotations

import os
import signal
import threading

import pytest

from pioneer.interrupt import Interrupted, deferred, handle_signals, kept


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_raises_interrupted_and_the_old_handlers_come_back(signum, code):
    before = signal.getsignal(signum)
    with pytest.raises(Interrupted) as info, handle_signals():
        signal.raise_signal(signum)
        pytest.fail("the signal did not stop the block")
    assert info.value.signum == signum
    assert info.value.exit_code == code
    assert info.value.name == signal.Signals(signum).name
    assert signal.getsignal(signum) is before


def test_a_deferred_block_ends_first_and_the_first_signal_wins():
    steps = []
    with pytest.raises(Interrupted) as info, handle_signals(), deferred():
        signal.raise_signal(signal.SIGTERM)
        steps.append("after the signal")
        with deferred():
            signal.raise_signal(signal.SIGINT)
            steps.append("inner block")
        steps.append("after the inner block")  # an inner block does not raise
    assert steps == ["after the signal", "inner block", "after the inner block"]
    assert info.value.signum == signal.SIGTERM


def test_an_error_inside_a_deferred_block_is_not_replaced():
    with pytest.raises(ValueError, match="the block's own"), handle_signals(), deferred():
        signal.raise_signal(signal.SIGINT)
        raise ValueError("the block's own error")


def test_signals_while_stopping_are_ignored():
    cleaned = []
    with handle_signals():
        with pytest.raises(Interrupted):
            signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)  # a second Ctrl-C during the clean-up
        signal.raise_signal(signal.SIGTERM)
        cleaned.append(True)
    assert cleaned == [True]


def test_the_innermost_run_names_what_it_kept_and_the_command_is_quoted():
    with (
        pytest.raises(Interrupted) as info,
        handle_signals(),
        kept(lambda: "the outputs kept in out"),
        kept(lambda: "3 of 9 episodes kept in out/eval/episodes.jsonl"),
    ):
        signal.raise_signal(signal.SIGINT)
    assert info.value.message(["pioneer", "eval", "--out", "my runs/a"]) == (
        "interrupted (SIGINT); 3 of 9 episodes kept in out/eval/episodes.jsonl; "
        "resume with: pioneer eval --out 'my runs/a'"
    )


def test_without_a_run_the_line_has_no_resume_hint():
    with pytest.raises(Interrupted) as info, handle_signals():
        signal.raise_signal(signal.SIGTERM)
    assert info.value.message(["pioneer", "run"]) == "interrupted (SIGTERM)"


def test_outside_the_main_thread_the_handlers_stay():
    before = signal.getsignal(signal.SIGINT)
    seen = []

    def body() -> None:
        with handle_signals():
            seen.append(signal.getsignal(signal.SIGINT))

    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    assert seen == [before]


def test_a_signal_held_when_the_block_failed_does_not_leak_into_later_blocks():
    """A signal arrives inside a deferred() block that then raises its own error: the error
    wins, and once the run is over no later deferred() block raises the held signal."""
    with pytest.raises(RuntimeError, match="own"), handle_signals(), deferred():
        os.kill(os.getpid(), signal.SIGINT)
        raise RuntimeError("own")
    with deferred():  # outside a run: nothing pending, nothing raised
        pass
