"""The OpenBLAS kernels (``OPENBLAS_CORETYPE``) this CPU can run besides the one numpy's OpenBLAS picks by itself,
one a line, for .ci/run to run the tests marked ``blas`` under each: a test that holds on one kernel only then fails
on the machine that wrote it.  x86-64 only (elsewhere: none): Haswell (AVX2 and FMA) and SkylakeX (AVX-512),
whichever the CPU's flags (/proc/cpuinfo) allow, and Sandybridge (AVX, no fused multiply-add) only where neither is
left besides the default: one rerun, about 85 s of the suite's time on 2 cores, covers the issue's pair (the default
and Haswell, or SkylakeX on a CPU with AVX-512); Sandybridge's rounding without FMA is by hand
(``OPENBLAS_CORETYPE=Sandybridge pytest -m blas``, DEVELOPERS.md)."""

from __future__ import annotations

import ctypes
import platform
import re
from pathlib import Path

import numpy  # noqa: F401  # loads numpy's OpenBLAS, whose kernel is asked below

KERNELS = (  # (OPENBLAS_CORETYPE, the CPU flags it needs)
    ("Sandybridge", {"avx"}),
    ("Haswell", {"avx2", "fma"}),
    ("SkylakeX", {"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"}),
)
FALLBACK = "Sandybridge"  # rerun only where no FMA kernel is left besides the default
CORENAME = ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename64_", "openblas_get_corename")


def cpu_flags() -> set[str]:
    try:
        m = re.search(r"^flags\s*:(.*)$", Path("/proc/cpuinfo").read_text(), re.MULTILINE)
    except OSError:
        return set()
    return set(m.group(1).split()) if m else set()


def default_kernel() -> str | None:
    """The kernel numpy's OpenBLAS chose (its core name), None if no loaded OpenBLAS says."""
    for line in Path("/proc/self/maps").read_text().splitlines():
        path = line.split()[-1]
        if "openblas" in Path(path).name.lower():
            lib = ctypes.CDLL(path)
            for name in CORENAME:
                if (fn := getattr(lib, name, None)) is not None:
                    fn.restype = ctypes.c_char_p
                    return fn().decode()
    return None


def kernels() -> list[str]:
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return []
    flags, default = cpu_flags(), (default_kernel() or "").lower()
    runnable = [name for name, need in KERNELS if need <= flags and name.lower() != default]
    return [name for name in runnable if name != FALLBACK] or runnable


if __name__ == "__main__":
    print("\n".join(kernels()))
