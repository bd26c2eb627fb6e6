"""The twin.machine record: written with every recording, read back, changed by the settings that
change floating-point results (in real subprocesses), shown by `twin info`; files without it still
load; identical runs on the same machine and settings still give byte-identical files."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from support.cli import TWIN

import twin
from twin.cli import main
from twin.record.machine import FLOAT_FLAGS, differences, machine, machine_text
from twin.record.mcap import schemas as S
from twin.record.mcap.info import read_info

KEYS = ["blas_core", "cpu", "cpu_flags", "libc", "libm_hwcaps", "numpy_simd"]
SETTINGS = ("OPENBLAS_CORETYPE", "GLIBC_TUNABLES", "NPY_DISABLE_CPU_FEATURES")
NUMPY_FLAGS = {"fma": "FMA3", "avx2": "AVX2", "avx512f": "AVX512F"}  # numpy's names of FLOAT_FLAGS
PRINT_MACHINE = "import json; from twin.record.machine import machine; print(json.dumps(machine()))"


def _env(**settings: str) -> dict[str, str]:
    """This process's environment without the floating-point settings, plus `settings`."""
    return {**{k: v for k, v in os.environ.items() if k not in SETTINGS}, **settings}


def _machine_in(**settings: str) -> dict[str, str]:
    """machine() as a new Python process started with `settings` reports it."""
    done = subprocess.run([sys.executable, "-c", PRINT_MACHINE], env=_env(**settings),
                          capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _uses_openblas() -> bool:
    blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
    return "openblas" in str(blas.get("name", "")).lower()


def _without_machine(source: Path, out: Path) -> Path:
    """A copy of `source` as twin wrote files before the record existed (mcap's own Writer)."""
    with open(source, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = list(reader.iter_messages(log_time_order=False))
        metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
        attachments = list(reader.iter_attachments())
    with open(out, "wb") as f:
        w = Writer(f)
        w.start(profile="", library=S.LIBRARY)
        schema_ids = {sid: w.register_schema(s.name, s.encoding, s.data)
                      for sid, s in summary.schemas.items()}
        channel_ids = {cid: w.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id])
                       for cid, c in summary.channels.items()}
        for name, record in metadata:
            if name != S.META_MACHINE:
                w.add_metadata(name, record)
        for a in attachments:
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        for _, _, m in messages:
            w.add_message(channel_ids[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
        w.finish()
    return out


def test_the_record_is_written_and_read_back(pick_place_mcap):
    path, _ = pick_place_mcap
    with open(path, "rb") as f:
        written = {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}
    record = written[S.META_MACHINE]
    assert list(record) == KEYS and all(isinstance(v, str) and v for v in record.values())
    assert record == machine()  # written by the recorder process, as this process sees its machine
    rec = twin.load(path)
    assert rec.machine == rec.meta[S.META_MACHINE] == record
    assert record["libc"] == " ".join(os.confstr("CS_GNU_LIBC_VERSION").split())
    if "NPY_DISABLE_CPU_FEATURES" not in os.environ:  # numpy's own detection agrees with cpuinfo
        from numpy._core._multiarray_umath import __cpu_features__ as found

        assert record["cpu_flags"] == (" ".join(f for f in FLOAT_FLAGS if found.get(NUMPY_FLAGS[f]))
                                       or "none")
    if _uses_openblas():
        assert record["blas_core"] != "unknown"


def test_the_record_is_gathered_once_and_handed_out_as_a_copy():
    first = machine()
    first["cpu"] = "changed"
    assert machine()["cpu"] != "changed" and machine() == machine()


@pytest.mark.skipif(not _uses_openblas(), reason="numpy is not built with OpenBLAS")
def test_openblas_coretype_changes_blas_core():
    skylake = _machine_in(OPENBLAS_CORETYPE="SkylakeX")
    haswell = _machine_in(OPENBLAS_CORETYPE="Haswell")
    assert (skylake["blas_core"], haswell["blas_core"]) == ("SkylakeX", "Haswell")
    assert differences(skylake, haswell) == ["blas_core"]
    assert "OpenBLAS SkylakeX" in machine_text(skylake)


def test_glibc_tunables_show_in_libm_hwcaps():
    plain = _machine_in()
    no_fma = _machine_in(GLIBC_TUNABLES="glibc.cpu.hwcaps=-AVX2,-FMA")
    assert (plain["libm_hwcaps"], no_fma["libm_hwcaps"]) == ("default", "-AVX2,-FMA")
    assert differences(plain, no_fma) == ["libm_hwcaps"]
    assert machine_text(no_fma).endswith("hwcaps -AVX2,-FMA)")
    other = _machine_in(GLIBC_TUNABLES="glibc.malloc.check=0:glibc.cpu.hwcaps=-AVX2")
    assert other["libm_hwcaps"] == "-AVX2"
    assert _machine_in(GLIBC_TUNABLES="glibc.malloc.check=0")["libm_hwcaps"] == "default"


def test_npy_disable_cpu_features_shows_in_numpy_simd():
    plain = _machine_in()
    if plain["numpy_simd"] == "none":
        pytest.skip("numpy dispatches to no SIMD target beyond its baseline here")
    off = _machine_in(NPY_DISABLE_CPU_FEATURES=plain["numpy_simd"])
    assert off["numpy_simd"] == "none" and differences(plain, off) == ["numpy_simd"]


def test_machine_text_and_differences():
    record = {"blas_core": "Haswell", "cpu": "AMD EPYC", "cpu_flags": "fma avx2",
              "libc": "glibc 2.36", "libm_hwcaps": "default", "numpy_simd": "X86_V3"}
    assert machine_text(record) == "AMD EPYC (fma avx2; OpenBLAS Haswell; numpy X86_V3; glibc 2.36)"
    old_cpu = {**record, "cpu_flags": "none", "libm_hwcaps": "-AVX2,-FMA"}
    assert machine_text(old_cpu) == ("AMD EPYC (no fma/avx2/avx512f; OpenBLAS Haswell; "
                                     "numpy X86_V3; glibc 2.36 hwcaps -AVX2,-FMA)")
    assert machine_text({}) == "? (?; OpenBLAS ?; numpy ?; libc ?)"
    assert differences(record, record) == []
    assert differences(record, old_cpu) == ["cpu_flags", "libm_hwcaps"]
    assert differences(record, {k: v for k, v in record.items() if k != "cpu"}) == ["cpu"]


def test_twin_info_prints_the_machine_line(pick_place_mcap, capsys):
    path, _ = pick_place_mcap
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert f"machine: {machine_text(machine())}" in out
    assert out.index(f"machine: {machine_text(machine())}") < out.index("channels:")


def test_a_file_without_the_record_still_loads_everywhere(pick_place_mcap, tmp_path, capsys):
    path, _ = pick_place_mcap
    old = _without_machine(path, tmp_path / "old.mcap")
    rec, new = twin.load(old), twin.load(path)
    assert S.META_MACHINE not in rec.meta and rec.machine == {}
    assert rec.frames.equals(new.frames) and rec.events == new.events and rec.urdf == new.urdf
    assert read_info(old).machine == {}
    assert main(["info", str(old)]) == 0
    assert "machine: not recorded" in capsys.readouterr().out.splitlines()
    assert main(["diff", str(old), str(path)]) == 0, capsys.readouterr().out


def test_identical_runs_on_the_same_settings_give_byte_identical_files(tmp_path):
    settings = {"OPENBLAS_CORETYPE": "Haswell", "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA"}
    files = []
    for name in ("one", "two"):
        folder = tmp_path / name
        folder.mkdir()
        done = subprocess.run([*TWIN, "run", "pick_place", "--cycles", "1", "--record", "run.mcap"],
                              cwd=folder, env=_env(HOME=str(folder), **settings),
                              capture_output=True, text=True, timeout=120, check=False)
        assert done.returncode == 0, done.stderr
        files.append(folder / "run.mcap")
    assert files[0].read_bytes() == files[1].read_bytes()
    recorded = twin.load(files[0]).machine
    assert recorded == _machine_in(**settings)
    assert (recorded["blas_core"], recorded["libm_hwcaps"]) == ("Haswell", "-AVX2,-FMA")
