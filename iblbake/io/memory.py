"""How much memory this process may still take: what every size check before work (a frame's
tiles, a chain, a decoded image, the API's estimates, the sheet's workers) compares against."""

from __future__ import annotations

import os


def host_bytes_available() -> int | None:
    """What this process may still allocate: the address-space limit (ulimit -v) less what it maps
    now, and the system's available memory, whichever is smaller."""
    limits = []
    try:
        import resource
        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft != resource.RLIM_INFINITY:
            with open("/proc/self/statm") as f:
                mapped = int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
            limits.append(soft - mapped)
    except (ImportError, OSError, ValueError):
        pass
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    limits.append(int(line.split()[1]) * 1024)
    except OSError:
        pass
    return min(limits) if limits else None
