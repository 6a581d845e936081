"""Where the models folder is: the repository's own ``models/`` unless STACK_MODELS_DIR says."""

from __future__ import annotations

from pathlib import Path

import pytest

from modelprep.files import MODELS_DIR_ENV, models_dir

REPO = Path(__file__).resolve().parents[3]


def test_the_default_models_folder_is_the_repositorys(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(MODELS_DIR_ENV, raising=False)
    assert models_dir() == REPO / "models"


def test_the_environment_names_another(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv(MODELS_DIR_ENV, str(tmp_path))
    assert models_dir() == tmp_path
