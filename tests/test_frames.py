"""Frame sources: read-ahead, and what each kind of --source gives."""

import threading

import numpy as np
import pytest

from lanelib.sources import ListSource, Prefetch


def numbered(n):
    return [np.full((4, 4, 3), i % 256, np.uint8) for i in range(n)]


def test_prefetch_gives_the_same_frames_in_order():
    source = Prefetch(ListSource(numbered(50)), depth=3)
    got = []
    while True:
        ok, frame, label = source.read()
        if not ok:
            break
        got.append((int(frame[0, 0, 0]), label))
    assert got == [(i, i) for i in range(50)]
    assert source.read()[0] is False  # stays ended
    source.release()


def test_prefetch_reads_ahead_on_another_thread():
    seen = []

    class Recording(ListSource):
        def read(self):
            seen.append(threading.current_thread().name)
            return super().read()

    source = Prefetch(Recording(numbered(5)))
    assert source.read()[0]
    source.release()
    assert seen and all(name == 'prefetch' for name in seen)


def test_prefetch_passes_a_read_error_to_the_loop():
    class Broken(ListSource):
        def read(self):
            raise OSError('disk gone')

    source = Prefetch(Broken([]))
    with pytest.raises(OSError, match='disk gone'):
        source.read()
    assert source.read()[0] is False
    source.release()


def test_release_stops_a_reader_that_is_ahead():
    source = Prefetch(ListSource(numbered(1000)), depth=2)
    source.read()
    assert 'prefetch' in [t.name for t in threading.enumerate()]
    source.release()
    assert 'prefetch' not in [t.name for t in threading.enumerate()]
