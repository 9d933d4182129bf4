"""How this process and the ones it starts hand freed memory back: :func:`keep_freed_memory`.

The surrogate and the evaluator make many short-lived arrays of 0.1–10 MB (a few thousand points times a
few dozen columns). glibc's malloc serves those from ``mmap`` or trims them off the heap's top when they are
freed, so the next one of the same size is fresh pages from the kernel, zeroed one page fault at a time: on
part B about a fifth of a surrogate pose's time in the cell (a verdict draw's ICP hardly notices;
benchmarks/README.md, "bench_cell_pose.py"). Raising both thresholds keeps such arrays on the heap, reused; an
array above the mmap threshold still goes back to the system when it is freed, and at most the trim
threshold of free heap is kept. Elsewhere than glibc this does nothing.
"""

from __future__ import annotations

import ctypes
import os

__all__ = ["keep_freed_memory", "HEAP_VARIABLES"]

_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's malloc.h
# bytes: arrays up to 16 MB reused from the heap, at most 64 MB of it kept free
HEAP_VARIABLES = {"MALLOC_MMAP_THRESHOLD_": 16 << 20, "MALLOC_TRIM_THRESHOLD_": 64 << 20}


def keep_freed_memory() -> bool:
    """Set both thresholds in this process (``mallopt``) and in the environment the processes it starts
    inherit (glibc reads it when a process starts), unless the environment sets them already; setting one
    alone turns off glibc's own adjustment of the other, so both are set together. True when glibc took them."""
    if any(name in os.environ for name in HEAP_VARIABLES):
        return False
    try:  # the C library this process already has (no ctypes.util.find_library: it runs ldconfig at every start)
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc: nothing to set
        return False
    os.environ.update({name: str(value) for name, value in HEAP_VARIABLES.items()})
    return bool(mallopt(_M_MMAP_THRESHOLD, HEAP_VARIABLES["MALLOC_MMAP_THRESHOLD_"])) and bool(
        mallopt(_M_TRIM_THRESHOLD, HEAP_VARIABLES["MALLOC_TRIM_THRESHOLD_"])
    )
