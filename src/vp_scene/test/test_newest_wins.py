"""The nodes' "newest plan wins" worker (vp_scene.node_runtime.NewestWins:
the dispatcher and recon nodes share it)."""
import threading
import time

from vp_scene.node_runtime import NewestWins


class _Log:
    def __init__(self):
        self.lines = []

    def warn(self, text):
        self.lines.append(text)


def _wait_for(cond, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, 'timed out'
        time.sleep(0.01)


def test_the_item_in_progress_ends_and_only_the_newest_waiting_one_follows():
    running, release, done, errors = threading.Event(), threading.Event(), [], []
    log = _Log()

    def handle(item):
        running.set()
        assert release.wait(10.0)
        if item == 'boom':
            raise RuntimeError('bad item')
        done.append(item)

    worker = NewestWins('test-worker', handle, lambda item, exc: errors.append((item, str(exc))), log,
                        'a newer plan arrived: it replaces the queued one').start()
    try:
        assert not worker.offer(1)
        assert running.wait(10.0)  # 1 in progress
        assert not worker.offer(2)
        assert worker.offer(3)  # replaces 2, logged
        assert log.lines == ['a newer plan arrived: it replaces the queued one']
        release.set()
        _wait_for(lambda: done == [1, 3])
        worker.offer('boom')  # an exception does not end the worker
        _wait_for(lambda: errors == [('boom', 'bad item')])
        worker.offer(4)
        _wait_for(lambda: done == [1, 3, 4])
    finally:
        worker.stop()
    assert worker.take() is None
    worker._thread.join(10.0)
    assert not worker._thread.is_alive()
