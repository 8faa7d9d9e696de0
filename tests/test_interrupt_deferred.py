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
