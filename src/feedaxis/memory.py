"""Freed memory given back to the system where a large case's analysis is about to peak
(glibc only; nothing happens elsewhere)."""
import ctypes

# From this many samples a sample-sized float64 array (32 MB) is mapped on its own
# (``feedaxis.__main__.MAPPED_BLOCK_BYTES``): below it the heap's freed blocks are what the
# next arrays reuse, and giving them back only costs page faults.
LARGE_CASE_SAMPLES = 1 << 22


def give_back_freed_memory(samples):
    """Return to the system what glibc's heap keeps of freed blocks for reuse (below
    ``feedaxis.__main__``'s 1 GB trim threshold), which would stay resident beside the
    peak that follows, on a case of at least ``LARGE_CASE_SAMPLES`` ``samples`` (before
    each candidate's fit in the diagnosis: its peak on 10^7 rows 1,463 -> 1,444 MB, one
    run each). Smaller cases keep them: on a 500 s tracking trace giving them back cost
    0.2 s of page faults (minor faults 128,000 -> 142,000)."""
    if samples < LARGE_CASE_SAMPLES:
        return
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass
