"""The OpenVINO backend without a model: auto's CPU rule, a missing runtime, bad options."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

from common.errors import BackendUnavailable, ConfigError
from runtimes import open_backend
from runtimes import select as sel

MODULE = "runtimes.openvino"


def cpuinfo(vendor: str, flags: str) -> str:
    """Two logical CPUs' worth of /proc/cpuinfo, as Linux writes it."""
    block = f"processor\t: {{n}}\nvendor_id\t: {vendor}\nmodel name\t: X\nflags\t\t: {flags}\n"
    return "\n".join(block.format(n=n) for n in range(2))


AMD_ZEN3 = cpuinfo("AuthenticAMD", "fpu sse2 avx avx2 fma f16c")
INTEL_AVX2 = cpuinfo("GenuineIntel", "fpu sse2 avx avx2 fma")
INTEL_AVX512_VNNI = cpuinfo("GenuineIntel", "avx2 avx512f avx512bw avx512_vnni")
INTEL_ALDER_LAKE = cpuinfo("GenuineIntel", "avx2 avx_vnni")
INTEL_SAPPHIRE_RAPIDS = cpuinfo("GenuineIntel", "avx512f amx_bf16 amx_tile amx_int8")
# The machine of docs/benchmarks.md where OpenVINO INT8 at 480 ran at 0.30x ONNX Runtime's time.
AMD_ZEN4_VNNI = cpuinfo("AuthenticAMD", "avx2 avx512f avx512bw avx512_vnni avx512_bf16")


@pytest.mark.parametrize(
    "info", [INTEL_AVX512_VNNI, INTEL_ALDER_LAKE, INTEL_SAPPHIRE_RAPIDS, AMD_ZEN4_VNNI]
)
def test_cpus_with_vnni_or_amx_suit_openvino_whatever_the_vendor(info: str) -> None:
    assert sel.openvino_cpu_reason(info) is None


@pytest.mark.parametrize(
    ("info", "reason"),
    [
        (AMD_ZEN3, "OpenVINO: this CPU has neither VNNI nor AMX"),
        (INTEL_AVX2, "OpenVINO: this CPU has neither VNNI nor AMX"),
        ("", "OpenVINO: the CPU's instruction flags are unknown"),
    ],
)
def test_other_cpus_keep_onnx_and_say_why(info: str, reason: str) -> None:
    assert sel.openvino_cpu_reason(info) == reason


def test_the_probe_reads_the_cpu_then_looks_for_the_runtime(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    amd, intel = tmp_path / "amd", tmp_path / "intel"
    amd.write_text(AMD_ZEN3)
    intel.write_text(INTEL_AVX512_VNNI)
    assert sel.probe_openvino(amd) == "OpenVINO: this CPU has neither VNNI nor AMX"
    assert sel.probe_openvino(tmp_path / "none") == (
        f"OpenVINO: cannot read {tmp_path / 'none'} to check the CPU"
    )
    assert sel.probe_openvino(intel) is None  # the dev extra installs openvino
    monkeypatch.setattr(sel, "_find", lambda module: module != "openvino")
    assert sel.probe_openvino(intel) == "OpenVINO not installed (pip install '.[openvino]')"


def test_auto_on_this_machine_follows_the_rule() -> None:
    expected = "openvino" if sel.openvino_cpu_reason(sel.CPUINFO.read_text()) is None else "onnx"
    no_gpu = {"tensorrt": lambda: "no GPU", "cuda": lambda: "no GPU"}
    name, _ = sel.resolve_backend("auto", {**sel.DEFAULT_PROBES, **no_gpu})
    assert name == expected


def test_auto_skips_openvino_for_a_precision_it_does_not_take(tmp_path: Path) -> None:
    """A GPU config's fp16 under auto on an Intel CPU: openvino refuses it, onnx runs."""
    taken: list[str] = []

    def openvino_load(model_path: Path, *, precision: str = "") -> object:
        taken.append("openvino")
        raise ConfigError(f"openvino takes precision fp32 or int8, not {precision!r}")

    def onnx_load(model_path: Path) -> object:
        taken.append("onnx")
        return "onnx backend"

    loaders = {"openvino": openvino_load, "onnx": onnx_load}
    probes: dict[str, sel.Probe] = {"tensorrt": lambda: "no GPU", "cuda": lambda: "no GPU"}
    probes.update(openvino=lambda: None, onnx=lambda: None)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sel, "load_function", loaders.__getitem__)
        chosen = sel.open_auto(tmp_path / "m.onnx", {"precision": "fp16"}, probes)
    assert chosen == "onnx backend"
    assert taken == ["openvino", "onnx"]


def test_a_missing_openvino_is_backend_unavailable(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "openvino", None)  # makes `import openvino` fail
    monkeypatch.delitem(sys.modules, MODULE, raising=False)
    with pytest.raises(BackendUnavailable, match=r"OpenVINO is not installed \(pip install"):
        open_backend("openvino", tmp_path / "m.onnx")
    with pytest.raises(ImportError):
        importlib.import_module("openvino")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"precision": "fp16"}, "openvino takes precision fp32 or int8, not 'fp16'"),
        ({"threads": 0}, "threads must be a positive integer, got 0"),
        ({"batch_profile": (1, 1, 1)}, "takes no option\\(s\\) batch_profile"),
    ],
)
def test_bad_options_are_config_errors(
    tmp_path: Path, options: dict[str, object], message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        open_backend("openvino", tmp_path / "m.onnx", **options)
