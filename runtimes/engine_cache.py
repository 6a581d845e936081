"""Where built TensorRT engines are kept, and when one may be reused.

A serialised engine is only valid for the exact model, GPU architecture, TensorRT version,
precision and batch profile it was built for; deserialising it anywhere else fails or, worse,
runs with the wrong tactics. Each engine therefore has a JSON sidecar holding its
:class:`EngineKey` plus its size and sha256, and :func:`check` compares that with the key wanted
now, saying which field changed (``engine cache miss: TensorRT version changed 10.3 → 10.5``).

Files, one slot per model name, precision and batch profile, so that fp16 and int8 engines of
one model live side by side and a TensorRT or GPU change replaces the slot's engine::

    <cache_dir>/<model>.<precision>.b<min>-<opt>-<max>.engine
    <cache_dir>/<model>.<precision>.b<min>-<opt>-<max>.json
    <cache_dir>/<model>.<model sha[:12]>.<calibration digest[:12]>.calib   (INT8 only)

The sidecar is written after the engine, each atomically, so a build killed half-way leaves a
slot that :func:`check` rejects rather than a truncated engine that looks valid.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common.errors import ConfigError
from common.files import atomic_write_bytes, sha256_file

SIDECAR_FORMAT = 1
PRECISIONS = ("fp32", "fp16", "int8")
MISS = "engine cache miss: "
HIT = "engine cache hit: "

#: Field -> how a change of it is described; the order is the order reasons are listed in.
_FIELD_LABELS = {
    "model_sha256": "model changed",
    "tensorrt_version": "TensorRT version changed",
    "gpu_name": "GPU changed",
    "compute_capability": "compute capability changed",
    "precision": "precision changed",
    "batch_profile": "batch profile changed",
    "calibration": "calibration data changed",
}


@dataclass(frozen=True, slots=True, kw_only=True)
class BuildOptions:
    """What the user asks of a TensorRT engine, validated before any minutes are spent.

    ``batch_profile`` is ``(min, opt, max)`` (a fixed-batch model overrides it);
    ``calib_dir`` is needed to build an int8 engine (without it, an int8 engine already in the
    cache is used whatever it was calibrated on); ``cache_dir`` None means ``<models>/engines``;
    ``workspace_gb`` caps the builder's scratch memory; ``device`` is the CUDA device index.
    """

    precision: str = "fp16"
    batch_profile: tuple[int, int, int] = (1, 1, 1)
    calib_dir: Path | None = None
    cache_dir: Path | None = None
    workspace_gb: float = 4.0
    device: int = 0

    def __post_init__(self) -> None:
        if self.precision not in PRECISIONS:
            raise ConfigError(
                f"TensorRT precision must be one of {', '.join(PRECISIONS)}, got {self.precision!r}"
            )
        if len(self.batch_profile) != 3:
            raise ConfigError(f"batch profile must be [min, opt, max], got {self.batch_profile}")
        lo, opt, hi = self.batch_profile
        if not 1 <= lo <= opt <= hi:
            raise ConfigError(f"batch profile must be 1 <= min <= opt <= max, got {lo}/{opt}/{hi}")
        if not self.workspace_gb > 0:
            raise ConfigError(f"workspace must be a positive number of GB, got {self.workspace_gb}")
        if self.device < 0:
            raise ConfigError(f"CUDA device index must be >= 0, got {self.device}")

    def folder(self) -> Path:
        """The engine cache folder: ``cache_dir``, or ``engines/`` beside the models."""
        if self.cache_dir is not None:
            return self.cache_dir
        from modelprep.files import models_dir  # not needed when a dir is given

        return models_dir() / "engines"


@dataclass(frozen=True, slots=True, kw_only=True)
class EngineKey:
    """Everything a built engine depends on.

    ``model_name`` (the model file's stem) only names the files; ``model_sha256`` is what
    identifies the model. ``compute_capability`` is ``"major.minor"``; ``batch_profile`` is
    ``(min, opt, max)``; ``calibration`` is the digest of the INT8 calibration images, empty
    for other precisions.
    """

    model_name: str
    model_sha256: str
    gpu_name: str
    compute_capability: str
    tensorrt_version: str
    precision: str
    batch_profile: tuple[int, int, int]
    calibration: str = ""

    def to_json(self) -> dict[str, Any]:
        """The key as a JSON-ready dict (the tuple becomes a list)."""
        data = dataclasses.asdict(self)
        data["batch_profile"] = list(self.batch_profile)
        return data

    @classmethod
    def from_json(cls, data: Any) -> EngineKey:
        """Rebuild a key from :meth:`to_json` output; ValueError if anything is off."""
        if not isinstance(data, dict):
            raise ValueError("key is not an object")
        names = {f.name for f in dataclasses.fields(cls)}
        if set(data) != names:
            raise ValueError(f"key fields {sorted(data)} differ from {sorted(names)}")
        profile = data["batch_profile"]
        if not (isinstance(profile, list) and len(profile) == 3):
            raise ValueError(f"batch_profile {profile!r} is not [min, opt, max]")
        if not all(isinstance(b, int) for b in profile):
            raise ValueError(f"batch_profile {profile!r} is not integers")
        strings = {k: v for k, v in data.items() if k != "batch_profile"}
        if not all(isinstance(v, str) for v in strings.values()):
            raise ValueError("key fields other than batch_profile must be strings")
        return cls(batch_profile=(profile[0], profile[1], profile[2]), **strings)

    def slot(self) -> str:
        """The file stem of this key's slot in the cache folder."""
        lo, opt, hi = self.batch_profile
        return f"{_safe(self.model_name)}.{self.precision}.b{lo}-{opt}-{hi}"


def _safe(name: str) -> str:
    """A file-name-safe version of ``name`` (model stems are ours, but be careful)."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name) or "model"


def engine_path(cache_dir: Path, key: EngineKey) -> Path:
    """The engine file for ``key``."""
    return cache_dir / f"{key.slot()}.engine"


def sidecar_path(cache_dir: Path, key: EngineKey) -> Path:
    """The JSON sidecar describing the engine in ``key``'s slot."""
    return cache_dir / f"{key.slot()}.json"


def calibration_cache_path(cache_dir: Path, key: EngineKey) -> Path:
    """The INT8 calibration cache for ``key``'s model and calibration images.

    Calibration scales depend on the network and the data, not on the GPU, so this file
    outlives engine rebuilds for a new GPU or TensorRT version (TensorRT itself ignores a
    cache written by another version).
    """
    return (
        cache_dir / f"{_safe(key.model_name)}.{key.model_sha256[:12]}.{key.calibration[:12]}.calib"
    )


def _show(field: str, value: object) -> str:
    if field == "model_sha256" and isinstance(value, str):
        return f"sha256 {value[:12]}"
    if field == "batch_profile" and isinstance(value, tuple):
        return "/".join(str(v) for v in value)
    if field == "calibration" and isinstance(value, str):
        return value[:12] or "none"
    return str(value)


def differences(cached: EngineKey, wanted: EngineKey, ignore: tuple[str, ...] = ()) -> list[str]:
    """One phrase per field that differs, e.g. ``TensorRT version changed 10.3 → 10.5``."""
    out = []
    for field, label in _FIELD_LABELS.items():
        if field in ignore:
            continue
        old, new = getattr(cached, field), getattr(wanted, field)
        if old != new:
            out.append(f"{label} {_show(field, old)} → {_show(field, new)}")
    return out


def _read_sidecar(path: Path) -> tuple[EngineKey, int, str]:
    """(key, engine size, engine sha256) from a sidecar; ValueError/OSError when unusable."""
    data = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
        raise ValueError(f"not a format-{SIDECAR_FORMAT} sidecar")
    size, digest = data.get("engine_bytes"), data.get("engine_sha256")
    if not isinstance(size, int) or not isinstance(digest, str):
        raise ValueError("engine_bytes or engine_sha256 missing")
    return EngineKey.from_json(data.get("key")), size, digest


def _nearest_other(cache_dir: Path, wanted: EngineKey) -> list[str]:
    """Why the other slots of the same model do not fit, for the nearest of them."""
    best: list[str] | None = None
    for path in sorted(cache_dir.glob(f"{_safe(wanted.model_name)}.*.json")):
        try:
            cached, _, _ = _read_sidecar(path)
        except (OSError, ValueError, TypeError):
            continue  # a broken neighbour explains nothing about this slot
        diff = differences(cached, wanted)
        if diff and (best is None or len(diff) < len(best)):
            best = diff
    return best or []


def check(
    cache_dir: Path, key: EngineKey, *, any_calibration: bool = False
) -> tuple[Path | None, str]:
    """``(engine path, reason)`` when ``key``'s cached engine is valid, else ``(None, reason)``.

    Reasons start with ``engine cache hit: `` or ``engine cache miss: `` and are meant to be
    logged as they are. ``any_calibration`` accepts an int8 engine calibrated on any images:
    for a service that was given no calibration folder but an engine built by ``export``.
    """
    engine, sidecar = engine_path(cache_dir, key), sidecar_path(cache_dir, key)
    if not sidecar.is_file():
        others = _nearest_other(cache_dir, key) if cache_dir.is_dir() else []
        where = f"no cached engine in {cache_dir} for {key.slot()}"
        return None, MISS + (f"{where}; nearest: {', '.join(others)}" if others else where)
    try:
        cached, size, digest = _read_sidecar(sidecar)
    except (OSError, ValueError, TypeError, UnicodeDecodeError) as exc:
        return None, MISS + f"sidecar {sidecar.name} is unreadable ({exc})"
    diff = differences(cached, key, ("calibration",) if any_calibration else ())
    if diff:
        return None, MISS + ", ".join(diff)
    if not engine.is_file():
        return None, MISS + f"engine file {engine.name} is missing"
    actual = engine.stat().st_size
    if actual != size:
        return None, MISS + f"engine file is {actual} bytes, sidecar says {size}"
    if sha256_file(engine) != digest:
        return None, MISS + "engine file sha256 does not match its sidecar"
    return engine, HIT + str(engine)


def store(cache_dir: Path, key: EngineKey, engine: bytes) -> Path:
    """Write ``engine`` and its sidecar into ``key``'s slot; returns the engine path.

    The sidecar goes last: until it is there the slot reads as a miss.
    """
    cache_dir.mkdir(parents=True, exist_ok=True)
    path, sidecar = engine_path(cache_dir, key), sidecar_path(cache_dir, key)
    sidecar.unlink(missing_ok=True)  # the old sidecar must not vouch for the new engine
    atomic_write_bytes(path, engine)
    meta = {
        "format": SIDECAR_FORMAT,
        "key": key.to_json(),
        "engine_bytes": len(engine),
        "engine_sha256": hashlib.sha256(engine).hexdigest(),
    }
    atomic_write_bytes(sidecar, (json.dumps(meta, indent=2) + "\n").encode())
    return path
