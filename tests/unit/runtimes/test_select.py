"""Backend selection: what ``auto`` picks with injected probes, and option handling."""

from __future__ import annotations

import importlib.util
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from common.errors import BackendUnavailable, ConfigError
from runtimes import (
    BACKENDS,
    Backend,
    open_backend,
    supported_options,
)
from runtimes import select as sel

NO_TRT = "TensorRT not installed"
NO_TORCH_GPU = "CUDA backend: PyTorch has no CUDA device"
NOT_INTEL = "OpenVINO: this CPU has neither VNNI nor AMX"


def probes(**results: str | None) -> dict[str, sel.Probe]:
    """Probes answering as given: None = usable, a string = the reason it is not."""
    return {name: (lambda r=reason: r) for name, reason in results.items()}


def test_auto_takes_tensorrt_first_when_everything_is_there() -> None:
    name, reason = sel.resolve_backend("auto", probes(tensorrt=None, cuda=None, onnx=None))
    assert (name, reason) == ("tensorrt", "auto: using tensorrt (GPU)")


def test_auto_takes_cuda_when_tensorrt_is_missing() -> None:
    name, reason = sel.resolve_backend("auto", probes(tensorrt=NO_TRT, cuda=None, onnx=None))
    assert name == "cuda"
    assert reason == f"auto: {NO_TRT}; falling back to cuda (GPU)"


def test_auto_falls_back_to_the_cpu_and_says_why_for_each() -> None:
    name, reason = sel.resolve_backend(
        "auto", probes(tensorrt=NO_TRT, cuda=NO_TORCH_GPU, openvino=NOT_INTEL, onnx=None)
    )
    assert name == "onnx"
    assert reason == f"auto: {NO_TRT}; {NO_TORCH_GPU}; {NOT_INTEL}; falling back to onnx (CPU)"


def test_auto_takes_openvino_before_onnx_where_it_probes_fine() -> None:
    name, reason = sel.resolve_backend(
        "auto", probes(tensorrt=NO_TRT, cuda=NO_TORCH_GPU, openvino=None, onnx=None)
    )
    assert (name, reason) == (
        "openvino",
        f"auto: {NO_TRT}; {NO_TORCH_GPU}; falling back to openvino (CPU)",
    )


def test_auto_with_nothing_usable_is_backend_unavailable() -> None:
    with pytest.raises(BackendUnavailable, match=r"no backend can run here: .*ONNX gone"):
        sel.resolve_backend(
            "auto",
            probes(tensorrt=NO_TRT, cuda=NO_TORCH_GPU, openvino=NOT_INTEL, onnx="ONNX gone"),
        )


def test_a_named_backend_is_taken_as_asked_without_probing() -> None:
    def boom() -> str | None:
        raise AssertionError("a named backend must not be probed")

    for name in BACKENDS:
        assert sel.resolve_backend(name, dict.fromkeys(sel.AUTO_ORDER, boom)) == (
            name,
            f"{name}: requested",
        )


def test_an_unknown_name_lists_the_valid_ones() -> None:
    with pytest.raises(
        ConfigError,
        match="unknown backend 'tpu'; valid backends: onnx, tensorrt, cuda, openvino, auto",
    ):
        sel.resolve_backend("tpu")


def test_real_probes_on_this_machine_answer_without_loading_a_model() -> None:
    assert sel.probe_onnx() is None
    if importlib.util.find_spec("tensorrt") is None:
        assert (sel.probe_tensorrt() or "").startswith(NO_TRT)
    name, reason = sel.resolve_backend("auto")
    assert name in BACKENDS
    assert reason.startswith("auto: ")


class FakeBackend:
    """Enough of a Backend for open_auto: it records the options it was loaded with."""

    def __init__(self, name: str, options: dict[str, Any]) -> None:
        self.name, self.options = name, options


def fake_loaders(
    fail: dict[str, str], monkeypatch: pytest.MonkeyPatch
) -> dict[str, Callable[..., Any]]:
    def tensorrt_load(model_path: Path, *, precision: str = "fp16", device: int = 0) -> Any:
        if "tensorrt" in fail:
            raise BackendUnavailable(fail["tensorrt"])
        return FakeBackend("tensorrt", {"precision": precision, "device": device})

    def onnx_load(model_path: Path, *, threads: int | None = None) -> Any:
        return FakeBackend("onnx", {"threads": threads})

    loaders = {"tensorrt": tensorrt_load, "onnx": onnx_load}
    monkeypatch.setattr(sel, "load_function", loaders.__getitem__)
    return loaders


def test_open_auto_drops_options_its_choice_does_not_take(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    fake_loaders({}, monkeypatch)
    with caplog.at_level(logging.INFO, logger=sel.__name__):
        backend: Any = sel.open_auto(
            Path("m.onnx"),
            {"precision": "int8", "threads": 2},
            probes(tensorrt=None, cuda="no torch", onnx=None),
        )
    assert backend.name == "tensorrt"
    assert backend.options == {"precision": "int8", "device": 0}
    assert "ignoring option(s) it does not take: threads" in caplog.text


def test_open_auto_falls_back_when_loading_fails_and_warns(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    fake_loaders({"tensorrt": "driver too old"}, monkeypatch)
    with caplog.at_level(logging.INFO, logger=sel.__name__):
        backend: Any = sel.open_auto(
            Path("m.onnx"),
            {},
            probes(tensorrt=None, cuda="no torch", openvino=NOT_INTEL, onnx=None),
        )
    assert backend.name == "onnx"
    record = caplog.records[-1]
    assert record.levelno == logging.WARNING
    assert record.getMessage() == (
        f"auto: no torch; {NOT_INTEL}; tensorrt: driver too old; falling back to onnx (CPU)"
    )


def test_supported_options_reads_the_load_signature() -> None:
    def fixed(model_path: Path, *, a: int = 1, b: str = "") -> Backend:
        raise NotImplementedError

    def anything(model_path: Path, **options: Any) -> Backend:
        raise NotImplementedError

    assert supported_options(fixed) == {"a", "b"}
    assert supported_options(anything) is None


def test_a_named_backend_refuses_an_option_it_does_not_take(tmp_path: Path) -> None:
    with pytest.raises(
        ConfigError,
        match="backend 'onnx' takes no option\\(s\\) precision; it takes: max_batch, threads",
    ):
        open_backend("onnx", tmp_path / "m.onnx", precision="fp16")


def test_a_missing_runtime_is_one_clear_backend_unavailable(tmp_path: Path) -> None:
    if importlib.util.find_spec("tensorrt") is not None:
        pytest.skip("TensorRT is installed here")
    with pytest.raises(BackendUnavailable, match=r"^TensorRT is not installed \(pip install"):
        open_backend("tensorrt", tmp_path / "m.onnx")


def test_backend_options_pass_only_what_was_set() -> None:
    assert sel.backend_options() == {}
    options = sel.backend_options("int8", (1, 2, 4))
    assert options == {"precision": "int8", "batch_profile": (1, 2, 4)}
    # The served batch, not detector.max_batch: one camera loads exactly as before.
    assert sel.backend_options(max_batch=3) == {"max_batch": 3}
