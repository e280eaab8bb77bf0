"""The conformance corpus: real public stages rendered small (issue 20).

Each ``tests/corpus/expected/<name>.json`` names a stage of the corpus
(``tests/usd_corpus.py`` says where it is) and what rendering it with
``mipray-record -w 96`` must give: the exit status, every warning and error
line (exactly; the corpus folder written ``$CORPUS``), the stats'
``unsupported`` list (exactly), and an image matching
``tests/corpus/references/<name>.png``, a render of the project's checked by
eye. ``MIPRAY_UPDATE_CORPUS=1`` rewrites the expectations and references from
what renders now, to be looked at and committed.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from usd_corpus import CORPUS, corpus_path, read_rgba

from mipray.record import main

HERE = Path(__file__).resolve().parent / "corpus"
EXPECTED = sorted((HERE / "expected").glob("*.json"))
UPDATE = os.environ.get("MIPRAY_UPDATE_CORPUS") == "1"
#: The width every stage renders at: enough to see, small enough for the suite.
WIDTH = 96


def _pixels_differ(ours: np.ndarray, reference: np.ndarray) -> float:
    """The fraction of pixels whose RGBA differs by more than 4/255 in any channel."""
    return float((np.abs(ours - reference) > 4.0 / 255.0).any(axis=2).mean())


@pytest.mark.parametrize("expected_file", EXPECTED, ids=[p.stem for p in EXPECTED])
def test_corpus_stage_renders_as_expected(
    expected_file: Path, tmp_path: Path, capsys, native
) -> None:
    expected = json.loads(expected_file.read_text())
    stage = corpus_path(expected["stage"])
    image, stats = tmp_path / "out.png", tmp_path / "stats.json"
    argv = [
        str(stage),
        str(image),
        "-w",
        str(WIDTH),
        "--stats",
        str(stats),
        *expected.get("argv", []),
    ]
    code = main(argv)
    err = capsys.readouterr().err.replace(str(CORPUS), "$CORPUS").replace(str(tmp_path), "$OUT")
    warnings = err.splitlines()
    listed = stats.read_text().replace(str(CORPUS), "$CORPUS") if stats.exists() else "null"
    unsupported = json.loads(listed)["unsupported"] if stats.exists() else None
    reference = HERE / "references" / f"{expected_file.stem}.png"
    if UPDATE:
        expected.update(exit=code, warnings=warnings, unsupported=unsupported)
        expected_file.write_text(json.dumps(expected, indent=2) + "\n")
        if image.exists():
            reference.write_bytes(image.read_bytes())
        pytest.skip("expectations rewritten")
    assert code == expected["exit"], err
    assert warnings == expected["warnings"]
    assert unsupported == expected["unsupported"]
    if expected["exit"] == 0:
        ours, theirs = read_rgba(image), read_rgba(reference)
        assert ours.shape == theirs.shape
        assert _pixels_differ(ours, theirs) < 0.005, f"{expected_file.stem}: see {image}"
