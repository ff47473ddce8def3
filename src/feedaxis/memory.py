"""glibc's heap for large cases: freed blocks kept for reuse by the command line, and given
back where a large case's analysis is about to peak (nothing happens off glibc)."""
import ctypes

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)
KEPT_BLOCK_BYTES = 1 << 30  # freed memory up to this much stays in the heap for reuse (a C int)
MAPPED_BLOCK_BYTES = 1 << 25  # a block this large (32 MB) is mapped on its own, unmapped when freed


def keep_freed_memory():
    """Let glibc's malloc keep freed blocks below ``MAPPED_BLOCK_BYTES`` in its heap for
    reuse instead of unmapping them: the analysis allocates and frees sample-sized arrays
    hundreds of times, and every fresh mapping is faulted in page by page (diagnose on
    10^6 rows spent 1.5 of its 5 CPU seconds in the kernel so). Larger blocks (a
    sample-sized array from 4·10^6 samples on) are still mapped on their own: reused in
    the heap, the holes between them held up to 300 MB more than the live arrays at
    10^7 rows (peak resident memory 2.3 GB where 1.8 GB was allocated), at 10 ms of the
    kernel's for each (diagnose on 10^7 rows: 4 -> 13 s). Set by the command line
    (``feedaxis.__main__``) only: a library leaves its host's allocator alone. Nothing
    changes off glibc."""
    mallopt = _glibc("mallopt")
    if mallopt is None:
        return
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt(M_MMAP_THRESHOLD, MAPPED_BLOCK_BYTES)
    mallopt(M_TRIM_THRESHOLD, KEPT_BLOCK_BYTES)


# From this many samples a sample-sized float64 array is a block mapped on its own
# (``MAPPED_BLOCK_BYTES``): below it the heap's freed blocks are what the next arrays reuse,
# and giving them back only costs page faults.
LARGE_CASE_SAMPLES = MAPPED_BLOCK_BYTES // 8  # 8 bytes a float64


def give_back_freed_memory(samples):
    """Return to the system what glibc's heap keeps of freed blocks for reuse (below the
    ``KEPT_BLOCK_BYTES`` :func:`keep_freed_memory` sets), which would stay resident beside
    the peak that follows, on a case of at least ``LARGE_CASE_SAMPLES`` ``samples`` (before
    each candidate's fit in the diagnosis: its peak on 10^7 rows 1,463 -> 1,444 MB, one
    run each). Smaller cases keep them: on a 500 s tracking trace giving them back cost
    0.2 s of page faults (minor faults 128,000 -> 142,000)."""
    if samples < LARGE_CASE_SAMPLES:
        return
    malloc_trim = _glibc("malloc_trim")
    if malloc_trim is not None:
        malloc_trim(0)


def _glibc(name):
    """glibc's function ``name``, or None off glibc."""
    try:
        return getattr(ctypes.CDLL("libc.so.6"), name)
    except (OSError, AttributeError):
        return None
