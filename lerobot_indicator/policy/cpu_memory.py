"""glibc's allocator told to keep freed memory in the process, so large tensors reuse pages already mapped."""

import ctypes
import ctypes.util
import functools

# mallopt parameters (glibc malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4


@functools.cache
def keep_freed_memory() -> bool:
    """Serve every allocation from the heap and never give freed heap memory back to the OS (glibc ``mallopt``).

    glibc maps each block above its mmap threshold (at most 32 MiB) afresh and unmaps it when freed, and trims
    the heap's free top. An image update allocates and frees dozens of such blocks (packed frames, feature
    maps and their gradients), so each is page-faulted in again on every update, one fault per 4 KiB page. On
    virtual machines that hand freed pages back to their host those faults are slow: on this project's 2-core
    VMs they took 0.1 s of system time per RGB-D update at 100 px, and the 3-step + inverse-dynamics update ran
    1.45x faster with freed memory kept (docs/results/README.md, "Update speed"). The process keeps its peak
    heap instead. Returns whether the setting took (False where the C library has no ``mallopt``)."""
    try:
        mallopt = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return bool(mallopt(M_MMAP_MAX, 0)) and bool(mallopt(M_TRIM_THRESHOLD, 2**31 - 1))
