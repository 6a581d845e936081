"""The sample photos read from scikit-image's files are skimage.data's own pixels, and reading
them does not import scikit-image (which would cost every camera process its memory)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from common.errors import ConfigError
from common.images import SAMPLES, load_sample


@pytest.mark.parametrize("name", SAMPLES)
def test_sample_pixels_are_skimage_data(name: str) -> None:
    from skimage import data

    loaders = {
        "astronaut": data.astronaut,
        "cameraman": data.camera,
        "chelsea": data.chelsea,
        "coffee": data.coffee,
        "rocket": data.rocket,
        "motorcycle": lambda: data.stereo_motorcycle()[0],
    }
    rgb = np.asarray(loaders[name](), dtype=np.uint8)
    expected = np.repeat(rgb[:, :, None], 3, axis=2) if rgb.ndim == 2 else rgb[:, :, ::-1]
    got = load_sample(name)
    assert got.dtype == np.uint8 and got.shape == expected.shape
    assert np.array_equal(got, expected)


def test_loading_a_sample_imports_neither_skimage_nor_scipy() -> None:
    code = (
        "import sys; from common.images import load_sample; load_sample('chelsea'); "
        "print(sorted(m for m in ('skimage', 'scipy') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"


def test_unknown_sample_names_the_samples() -> None:
    with pytest.raises(ConfigError, match="chelsea"):
        load_sample("nope")
