"""``interrupt.deferred``: a signal arriving while a result line is written and counted is raised
only when that block ends, so the interruption's line counts exactly the lines written."""
import os
import signal

import pytest

from optplan import interrupt


def test_a_signal_inside_deferred_is_raised_after_the_block_with_its_count():
    written = []
    with pytest.raises(interrupt.Interrupted), interrupt.handling("t", quiet=False):
        interrupt.progress(0, 3, "trial runs")
        for k in range(3):
            with interrupt.deferred():
                written.append(k)
                if k == 1:
                    os.kill(os.getpid(), signal.SIGINT)   # arrives between the write and the count
                    for _ in range(1000):                 # the handler runs within these bytecodes
                        pass
                    written.append("still in the block")
                interrupt.progress(k + 1, 3, "trial runs")
    assert written == [0, 1, "still in the block"]   # the block finished; the loop stopped after it
    assert "after 2 of 3 trial runs" in interrupt.message()


def test_nested_deferred_blocks_raise_at_the_outermost_end():
    with pytest.raises(interrupt.Interrupted), interrupt.handling("t", quiet=False):
        with interrupt.deferred():
            with interrupt.deferred():
                os.kill(os.getpid(), signal.SIGINT)
                for _ in range(1000):
                    pass
            reached = True   # the inner block's end does not raise
        assert reached


def test_without_a_signal_deferred_does_nothing():
    with interrupt.handling("t", quiet=False):
        with interrupt.deferred():
            x = 1
    assert x == 1 and interrupt.received() is None


def _spin():
    for _ in range(1000):   # a Python signal handler runs within these bytecodes
        pass


def test_a_signal_inside_committing_is_ignored_and_the_block_completes():
    """The block writing a command's success record: a signal from its start on neither raises nor counts, and the
    handlers are restored when ``handling`` ends."""
    before = signal.getsignal(signal.SIGTERM)
    done = []
    with interrupt.handling("t", quiet=False):
        with interrupt.committing():
            os.kill(os.getpid(), signal.SIGTERM)
            _spin()
            done.append("record written")
        os.kill(os.getpid(), signal.SIGINT)               # after the block too: the command is complete
        _spin()
        interrupt.check()
        assert interrupt.received() is None
    assert done == ["record written"]
    assert signal.getsignal(signal.SIGTERM) is before


def test_a_signal_before_committing_is_raised_on_entry():
    body = []
    with pytest.raises(interrupt.Interrupted), interrupt.handling("t", quiet=False):
        with interrupt.deferred():                        # the signal recorded, not raised, inside this block ...
            os.kill(os.getpid(), signal.SIGTERM)
            _spin()
            with interrupt.committing():                  # ... so committing's check on entry raises it
                body.append("written")
    assert body == []


def test_committing_outside_handling_only_checks():
    before = {s: signal.getsignal(s) for s in interrupt.SIGNALS}
    with interrupt.committing():
        pass
    assert {s: signal.getsignal(s) for s in interrupt.SIGNALS} == before
