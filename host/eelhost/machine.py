"""The machine a figure was measured on (CPU, SIMD, load), for the provenance of benchmark figures.

A library module: the benchmarks and the commands that write measured figures (`eelbot plan
--bench`, `eelbot run --bench`) cite the machine with it.
"""

from __future__ import annotations

import platform
from pathlib import Path

__all__ = ["cpu_model", "load_average", "simd_flags"]


def cpu_model() -> str:
    """The CPU's model name (from /proc/cpuinfo), for the provenance of benchmark figures."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def simd_flags() -> str:
    """Which of AVX, AVX2, FMA, AVX-512F the CPU has (from /proc/cpuinfo)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return "unknown"
    flags = next(
        (ln.split(":", 1)[1].split() for ln in text.splitlines() if ln.startswith("flags")), []
    )
    wanted = ("avx", "avx2", "fma", "avx512f")
    return " ".join(f for f in wanted if f in flags) or "none of avx/avx2/fma/avx512f"


def load_average() -> str:
    """The 1, 5 and 15 minute load averages (from /proc/loadavg)."""
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "unknown"
