"""Freed heap memory given back to the system (:mod:`feedaxis.memory`)."""
import sys

import pytest

from feedaxis.memory import LARGE_CASE_SAMPLES, give_back_freed_memory


def resident_mb():
    with open("/proc/self/status", encoding="ascii") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's heap, /proc")
def test_freed_blocks_below_the_heap_top_leave_the_resident_memory():
    """128 MB of 64 kB blocks freed under one still held at the heap's top stay resident
    (glibc trims only the top), also when the case is too small to give them back, until
    given back for a large one."""
    blocks = [bytearray(1 << 16) for _ in range(2048)]
    top = blocks.pop()
    held = resident_mb()
    del blocks
    freed = resident_mb()
    give_back_freed_memory(LARGE_CASE_SAMPLES - 1)
    kept = resident_mb()
    give_back_freed_memory(LARGE_CASE_SAMPLES)
    assert held - freed < 32 and freed - kept < 32 < kept - resident_mb()
    del top


def test_without_glibc_nothing_happens(monkeypatch):
    import ctypes

    def missing(name):
        raise OSError(name)

    monkeypatch.setattr(ctypes, "CDLL", missing)
    assert give_back_freed_memory(LARGE_CASE_SAMPLES) is None
