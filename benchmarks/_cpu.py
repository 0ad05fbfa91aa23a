"""CPU time of finished child processes, for benchmarks that time a subprocess (ngspice, a training run) by CPU."""

from __future__ import annotations


def children_cpu() -> float:
    """User + system CPU seconds of this process's waited-for children (``resource.RUSAGE_CHILDREN``)."""
    import resource
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime
