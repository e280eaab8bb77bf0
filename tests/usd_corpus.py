"""Where the USD conformance corpus is, and image comparisons the corpus tests share.

The corpus (stages, textures and OpenUSD's usdrecord baselines, from public
repositories with their licences) is data the workplace lays out beside the
repository, as ``shared/osd-shapes`` is: ``../shared/usd-corpus`` (or
``$MIPRAY_USD_CORPUS``). ``tests/corpus/MANIFEST.tsv`` lists every file, the
repository and commit it comes from; ``tests/corpus/README.md`` says more.
Tests that need it skip, naming the path, when it is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

__all__ = ["CORPUS", "corpus_path", "coverage", "coverage_match", "read_rgba"]

CORPUS = Path(
    os.environ.get("MIPRAY_USD_CORPUS")
    or Path(__file__).resolve().parent.parent.parent / "shared" / "usd-corpus"
)


def corpus_path(*parts: str) -> Path:
    """A path inside the corpus; skips the test when the corpus (or that file) is absent."""
    path = CORPUS.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"{path} is absent: the USD corpus is laid out as tests/corpus/README.md says")
    return path


def read_rgba(path: Path) -> NDArray[np.float32]:
    """An image as H×W×4 floats in [0, 1] (alpha 1 where the file has none)."""
    from mipray import _mipray

    pixels, _ = _mipray.read_image(str(path))
    if pixels.shape[2] == 4:
        return pixels.astype(np.float32)
    alpha = np.ones((*pixels.shape[:2], 1), np.float32)
    return np.concatenate([pixels[..., :3], alpha], axis=2).astype(np.float32)


def coverage(image: NDArray[np.float32]) -> NDArray[np.bool_]:
    """Pixels more than half covered (alpha > 0.5)."""
    return np.asarray(image[..., 3] > 0.5)


def coverage_match(ours: NDArray[np.float32], theirs: NDArray[np.float32]) -> tuple[float, int]:
    """(intersection over union of the two coverages, largest bounding-box edge offset in
    pixels): framing and coverage, which do not depend on the renderer."""
    a, b = coverage(ours), coverage(theirs)
    union = np.logical_or(a, b).sum()
    iou = float(np.logical_and(a, b).sum() / union) if union else 1.0
    if not a.any() or not b.any():
        return iou, max(a.shape)
    boxes = []
    for mask in (a, b):
        rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
        boxes.append(np.array([rows[0], rows[-1], cols[0], cols[-1]]))
    return iou, int(np.abs(boxes[0] - boxes[1]).max())
