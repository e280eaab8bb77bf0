"""A render's AOVs stay in the buffers the renderer filled: ``RenderResult.aovs`` and each
progressive pass hand out read-only numpy views of them, never copies, and writing a result
from those views gives the file that writing copies of the same pixels gives.

The truths are numpy's own account of memory (``ctypes.data``, ``np.shares_memory``, the
``base`` chain and the flags) and, for the files, the same writer fed owned copies of the
pixels (how a result was written when its arrays were copies).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import mipray
from mipray.image import write_aovs

from stages import add_camera, add_cube, add_distant_light, new_stage

AOVS = ("color", "depth", "normal")


def lit_cube():
    stage = new_stage()
    add_cube(stage, "/World/Cube", scheme="catmullClark")
    add_camera(stage, "/World/Cam", eye=(0.2, 0.3, 2.6))
    add_distant_light(stage, "/World/Sun", intensity=3.0)
    return stage


@pytest.fixture(scope="module")
def result() -> mipray.RenderResult:
    pytest.importorskip("mipray._mipray")
    return mipray.render(lit_cube(), width=32, aovs=AOVS, settings={"samples": 2, "seed": 1})


def test_result_arrays_are_read_only_views_of_one_owner(native, result) -> None:
    owner = result.aovs["color"].base
    assert owner is not None and not isinstance(owner, np.ndarray)
    assert list(owner) == list(owner.keys()) == list(AOVS) and len(owner) == len(AOVS)
    h, w = result.height, result.width
    for name, channels in zip(AOVS, (3, 1, 3), strict=True):
        kept = result.aovs[name]
        assert kept.base is owner, name
        assert kept.shape == (h, w, channels) and kept.dtype == np.float32, name
        assert kept.flags.c_contiguous and not kept.flags.owndata, name
        # Asked again: a new array object over the same bytes, not a copy.
        again = owner[name]
        assert again is not kept and again.ctypes.data == kept.ctypes.data, name
        assert np.shares_memory(again, kept), name
        np.testing.assert_array_equal(again, kept, err_msg=name)
    # The AOVs are distinct buffers, not one memory seen three ways.
    assert not np.shares_memory(owner["color"], owner["normal"])
    assert "alpha" not in owner and owner.get("alpha") is None
    with pytest.raises(KeyError):
        owner["alpha"]
    assert [n for n, _ in owner.items()] == list(AOVS) and len(owner.values()) == len(AOVS)


def test_views_cannot_be_written_or_made_writeable(native, result) -> None:
    color = result.aovs["color"]
    assert not color.flags.writeable
    with pytest.raises(ValueError):
        color[0, 0, 0] = 1.0
    with pytest.raises(ValueError):
        color.flags.writeable = True
    # A copy is the caller's to change, and changing it leaves the render's buffer alone.
    mine = np.array(color)
    mine[...] = -1.0
    assert (result.aovs["color"] >= 0.0).all()


def test_a_view_keeps_the_buffers_alive(native) -> None:
    r = mipray.render(lit_cube(), width=16, aovs=("color",), settings={"seed": 1})
    color = r.aovs["color"]
    expected = np.array(color)
    del r
    import gc

    gc.collect()
    # Reading freed memory would give garbage (or crash); the view holds its owner.
    np.testing.assert_array_equal(color, expected)


@pytest.mark.parametrize("name", ["beauty.exr", "beauty.png", "beauty.tif"])
def test_writing_the_views_writes_what_writing_copies_wrote(
    native, result, tmp_path: Path, name: str
) -> None:
    from_views = tmp_path / "views" / name
    from_copies = tmp_path / "copies" / name
    result.write(from_views)
    copies = {k: np.array(v) for k, v in result.aovs.items()}
    assert all(c.flags.owndata for c in copies.values())
    write_aovs(from_copies, copies, metadata=result.metadata())
    got, got_channels = native.read_image(str(from_views))
    want, want_channels = native.read_image(str(from_copies))
    assert got_channels == want_channels
    # Bit for bit, NaN and signed zeros included.
    assert got.shape == want.shape
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    assert native.read_metadata(str(from_views)) == native.read_metadata(str(from_copies))
    assert (got > 0.0).any(), "the file holds the lit cube, not an empty image"


def test_each_progressive_pass_keeps_its_own_buffers(native) -> None:
    passes: list[tuple[int, dict[str, np.ndarray], dict[str, np.ndarray]]] = []

    def on_update(samples: int, converged: bool, aovs: dict[str, np.ndarray]) -> None:
        # The arrays as handed over, and a copy of their values at that moment.
        passes.append((samples, aovs, {k: np.array(v) for k, v in aovs.items()}))

    final = mipray.render(
        lit_cube(),
        width=24,
        aovs=("color", "depth"),
        settings={"samples": 4, "seed": 2},
        progressive=True,
        on_update=on_update,
    )
    assert [s for s, _, _ in passes] == [1, 2, 4]
    owners = [aovs["color"].base for _, aovs, _ in passes]
    assert len({id(o) for o in owners}) == len(owners), "each pass has buffers of its own"
    for samples, aovs, then in passes:
        assert isinstance(aovs, dict) and list(aovs) == ["color", "depth"]
        for k, v in aovs.items():
            assert not v.flags.writeable and v.base is aovs["color"].base, (samples, k)
            # Later passes did not write into an earlier pass's arrays.
            np.testing.assert_array_equal(v, then[k], err_msg=f"{samples}: {k}")
    # The passes differ (1 sample is rougher than 4), so the check above could see a reuse.
    assert not np.array_equal(passes[0][2]["color"], passes[-1][2]["color"])
    np.testing.assert_array_equal(passes[-1][1]["color"], final.aovs["color"])
