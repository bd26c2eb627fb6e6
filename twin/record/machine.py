"""Where a recording was made: the CPU and the settings that change floating-point results (the
`twin.machine` metadata record). Strings only, no time: the same machine and settings give the same
record, so identical runs there still give byte-identical files."""

from __future__ import annotations

import ctypes
import os
import platform
from functools import cache
from pathlib import Path

FLOAT_FLAGS = ("fma", "avx2", "avx512f")  # the CPU features that change numpy's and libm's results
_CORENAME_SYMBOLS = ("openblas_get_corename", "openblas_get_corename64_",
                     "scipy_openblas_get_corename64_", "scipy_openblas_get_corename")


def machine() -> dict[str, str]:
    """This process's machine record (gathered once per process): cpu, cpu_flags, blas_core, libc,
    libm_hwcaps and numpy_simd, by sorted key."""
    return dict(_gathered())


@cache
def _gathered() -> tuple[tuple[str, str], ...]:
    info = _cpuinfo()
    record = {
        "cpu": _cpu_name(info),
        "cpu_flags": " ".join(f for f in FLOAT_FLAGS if f in _flags(info)) or "none",
        "blas_core": _blas_core(),
        "libc": " ".join(platform.libc_ver()).strip() or "unknown",
        "libm_hwcaps": _hwcaps(os.environ.get("GLIBC_TUNABLES", "")),
        "numpy_simd": _numpy_simd(),
    }
    return tuple(sorted(record.items()))


def machine_text(record: dict[str, str]) -> str:
    """One short line, e.g. "AMD EPYC (fma avx2; OpenBLAS Haswell; numpy X86_V3; glibc 2.36)"."""
    flags = record.get("cpu_flags", "?")
    hwcaps = record.get("libm_hwcaps", "default")
    libc = record.get("libc", "libc ?") + ("" if hwcaps == "default" else f" hwcaps {hwcaps}")
    parts = ["no " + "/".join(FLOAT_FLAGS) if flags == "none" else flags,
             f"OpenBLAS {record.get('blas_core', '?')}",
             f"numpy {record.get('numpy_simd', '?')}", libc]
    return f"{record.get('cpu', '?')} ({'; '.join(parts)})"


def differences(a: dict[str, str], b: dict[str, str]) -> list[str]:
    """The keys whose values differ between two machine records (one missing counts), sorted."""
    return sorted(k for k in a.keys() | b.keys() if a.get(k) != b.get(k))


def _cpuinfo() -> dict[str, str]:
    """The first processor's fields in /proc/cpuinfo (empty where there is none)."""
    fields: dict[str, str] = {}
    try:
        text = Path("/proc/cpuinfo").read_text(errors="replace")
    except OSError:
        return fields
    for line in text.splitlines():
        if not line.strip() and fields:
            break  # the first processor's block ends
        name, sep, value = line.partition(":")
        if sep:
            fields.setdefault(name.strip().lower(), " ".join(value.split()))
    return fields


def _cpu_name(info: dict[str, str]) -> str:
    return info.get("model name") or platform.processor() or "unknown"


def _flags(info: dict[str, str]) -> set[str]:
    return set((info.get("flags") or info.get("features") or "").split())


def _blas_core() -> str:
    """The kernel numpy's OpenBLAS chose at load (OPENBLAS_CORETYPE forces it), asked of the loaded
    library itself; "unknown" when numpy uses another BLAS or the library cannot be found."""
    import numpy  # noqa: F401 - loads its BLAS

    for path in _loaded_openblas():
        try:
            lib = ctypes.CDLL(path, mode=getattr(os, "RTLD_NOLOAD", 0))  # the copy already loaded
        except OSError:
            continue
        for symbol in _CORENAME_SYMBOLS:
            get = getattr(lib, symbol, None)
            if get is not None:
                get.restype = ctypes.c_char_p
                return (get() or b"unknown").decode(errors="replace").strip() or "unknown"
    return "unknown"


def _loaded_openblas() -> list[str]:
    """Paths of the OpenBLAS libraries mapped into this process, numpy's own first."""
    try:
        lines = Path("/proc/self/maps").read_text().splitlines()
    except OSError:
        return []
    paths = {p for p in (line.split(None, 5)[-1] for line in lines if "/" in line)
             if "openblas" in os.path.basename(p).lower()}
    return sorted(paths, key=lambda p: ("numpy" not in p, p))


def _hwcaps(tunables: str) -> str:
    """The glibc.cpu.hwcaps part of a GLIBC_TUNABLES value ("a=x:b=y"), or "default"."""
    for item in tunables.split(":"):
        name, _, value = item.partition("=")
        if name.strip() == "glibc.cpu.hwcaps" and value:
            return value
    return "default"


def _numpy_simd() -> str:
    """numpy's SIMD dispatch targets found at run time, less any NPY_DISABLE_CPU_FEATURES names."""
    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:
        return "unknown"
    features = getattr(umath, "__cpu_features__", {})
    found = [t for t in getattr(umath, "__cpu_dispatch__", []) if features.get(t)]
    return " ".join(found) or "none"
