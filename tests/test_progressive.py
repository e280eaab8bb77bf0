"""Progressive rendering from Python and mipray-record: every pass's image reaches the caller,
the last one is the result and a one-pass render's, and a failing callback stops the render.

The ``native`` tests go through the compiled delegate end to end; the rest check the command
line's own logic (pass labels, atomic writes) with the fake module.
"""

from __future__ import annotations

import io
import threading
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd

import mipray
from mipray import record

from stages import add_camera, add_cube, add_distant_light, new_stage

WIDTH = 40
AOVS = ("color", "depth")


def stage_with_soft_shadows() -> Usd.Stage:
    """A subdivided cube under a distant light with an angle: soft shadows, so every pass
    adds noise-reducing samples inside the image as well as at the edges."""
    stage = new_stage()
    add_cube(stage, "/World/Cube", scheme="catmullClark")
    floor = [(-4.0, -0.5, -4.0), (4.0, -0.5, -4.0), (4.0, -0.5, 4.0), (-4.0, -0.5, 4.0)]
    add_cube(stage, "/World/Floor", points=floor, counts=[4], indices=[0, 3, 2, 1], scheme="none")
    add_camera(stage, "/World/Cam", eye=(1.0, 1.0, 9.0))
    add_distant_light(stage, "/World/Sun")
    return stage


class Updates:
    """Records every ``on_update`` call: samples, converged, the arrays, the calling thread."""

    def __init__(self) -> None:
        self.calls: list[tuple[int, bool, dict[str, np.ndarray]]] = []
        self.threads: set[int] = set()

    def __call__(self, samples: int, converged: bool, aovs: dict[str, np.ndarray]) -> None:
        self.threads.add(threading.get_ident())
        self.calls.append((samples, converged, aovs))


def one_pass(samples: int, seed: int = 3) -> mipray.RenderResult:
    """A render of fixed sample count on a fresh session (see the bit-identity test)."""
    settings = {"samples": samples, "seed": seed}
    with mipray.RenderSession(stage_with_soft_shadows()) as session:
        return session.render(width=WIDTH, aovs=AOVS, settings=settings)


def test_each_pass_reaches_on_update_and_the_last_is_the_result(native) -> None:
    updates = Updates()
    with mipray.RenderSession(stage_with_soft_shadows()) as session:
        result = session.render(
            width=WIDTH,
            aovs=AOVS,
            settings={"samples": 8, "seed": 3},
            progressive=True,
            on_update=updates,
        )
    assert [(s, c) for s, c, _ in updates.calls] == [
        (1, False),
        (2, False),
        (4, False),
        (8, True),
    ]
    h, w = result.height, result.width
    for _, _, aovs in updates.calls:
        assert list(aovs) == list(AOVS)
        assert aovs["color"].shape == (h, w, 3) and aovs["depth"].shape == (h, w, 1)
        assert all(a.dtype == np.float32 for a in aovs.values())
        assert np.isfinite(aovs["color"]).all()
    last = updates.calls[-1][2]
    for name in AOVS:
        np.testing.assert_array_equal(last[name], result.aovs[name], err_msg=name)
    first = updates.calls[0][2]["color"]
    changed = np.abs(first - result.aovs["color"]).max(axis=-1) > 1e-4
    assert changed.sum() > 0.02 * h * w, "the first pass (1 sample) is rougher than the final"
    # The callback ran on a render thread: it could only take the GIL because the calling
    # thread had released it for the render.
    assert threading.get_ident() not in updates.threads


@pytest.mark.parametrize("samples, passes", [(8, [1, 2, 4, 8]), (6, [1, 2, 4, 6])])
def test_progressive_ends_bit_identical_to_one_pass(native, samples: int, passes: list) -> None:
    # Each render on its own session: a delegate's geometry cache outlives a render, and split
    # subpatches' cache ids are not yet stable across renders (known, reported in
    # plugin/tests/progressive.rs), so a second render on a warm cache may differ by rounding.
    updates = Updates()
    progressive = mipray.render(
        stage_with_soft_shadows(),
        width=WIDTH,
        aovs=AOVS,
        settings={"samples": samples, "seed": 3},
        progressive=True,
        on_update=updates,
    )
    assert [s for s, _, _ in updates.calls] == passes == record.pass_samples(samples)
    reference = one_pass(samples)
    for name in AOVS:
        np.testing.assert_array_equal(progressive.aovs[name], reference.aovs[name], err_msg=name)
    other_seed = one_pass(samples, seed=4)
    assert not np.array_equal(progressive.aovs["color"], other_seed.aovs["color"])


def test_without_progressive_on_update_sees_one_pass(native) -> None:
    updates = Updates()
    result = mipray.render(
        stage_with_soft_shadows(),
        width=WIDTH,
        aovs=("color",),
        # progressive=False wins over the setting.
        settings={"samples": 4, "seed": 3, "progressive": 1},
        progressive=False,
        on_update=updates,
    )
    assert [(s, c) for s, c, _ in updates.calls] == [(4, True)]
    np.testing.assert_array_equal(updates.calls[0][2]["color"], result.aovs["color"])


class StopRender(Exception):
    pass


@pytest.mark.parametrize("error", [StopRender("enough"), ValueError("not a setting error")])
def test_exception_in_on_update_stops_the_render_and_propagates(native, error: Exception) -> None:
    seen: list[int] = []
    done: list[tuple[int, int]] = []

    def on_update(samples: int, converged: bool, aovs: dict[str, np.ndarray]) -> None:
        seen.append(samples)
        if samples == 2:
            raise error

    with mipray.RenderSession(stage_with_soft_shadows()) as session:
        with pytest.raises(type(error)) as info:
            session.render(
                width=WIDTH,
                aovs=AOVS,
                settings={"samples": 16, "seed": 3},
                progressive=True,
                on_update=on_update,
                progress=lambda d, t: done.append((d, t)),
            )
        assert info.value is error, "the callback's own exception, not a translation"
        assert seen == [1, 2], "no update after the failing one"
        pixels = done[-1][1] // 16
        assert max(d for d, _ in done) <= 2 * pixels, "cancelled: the 4-sample pass never ran"
        # The session is still usable, and renders what a fresh one does.
        again = session.render(width=WIDTH, aovs=AOVS, settings={"samples": 2, "seed": 3})
    reference = one_pass(2)
    for name in AOVS:
        np.testing.assert_array_equal(again.aovs[name], reference.aovs[name], err_msg=name)


def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "scene.usda"
    stage = stage_with_soft_shadows()  # held: the layer handle dies with the stage
    stage.GetRootLayer().Export(str(path))
    return path


def test_record_progressive_rewrites_the_image_each_pass(
    native, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    scene = scene_file(tmp_path)
    out_dir = tmp_path / "out"
    out = out_dir / "shot.exr"
    plain = tmp_path / "plain.exr"
    common = ["-w", str(WIDTH), "--aovs", "color,depth", "--samples", "8", "--seed", "3"]
    assert record.main([*common, str(scene), str(plain)]) == 0

    # What a viewer watching the file would see: the renderer writes each pass (a temporary
    # file renamed onto it) before the command hears of the pass.
    seen: list[tuple[int, np.ndarray, list[str], str]] = []
    real_pass_finished = record._Progress.pass_finished

    def pass_finished(self: record._Progress, samples: int) -> None:
        real_pass_finished(self, samples)
        if samples < 8:
            tagged = native.read_metadata(str(out))["mipray:progressiveSamples"]
            listing = sorted(p.name for p in out_dir.iterdir())
            seen.append((samples, native.read_image(str(out))[0], listing, tagged))

    monkeypatch.setattr(record._Progress, "pass_finished", pass_finished)
    code = record.main(["--progressive", *common, str(scene), str(out)])
    monkeypatch.setattr(record._Progress, "pass_finished", real_pass_finished)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert captured.out.splitlines()[-1] == str(out)
    # Passes 1, 2, 4 written as they finish, then the final image with its stats.
    assert [(s, tagged) for s, _, _, tagged in seen] == [(1, "1"), (2, "2"), (4, "4")]
    for _, _, listing, _ in seen:
        assert listing == ["shot.exr"], "the temporary file is renamed before the pass is told"
    final, names = native.read_image(str(out))
    assert names == ["R", "G", "B", "Z"]
    assert "mipray:progressiveSamples" not in native.read_metadata(str(out))
    assert not np.array_equal(seen[-1][1], final), "the last pass is the result, written after"
    assert np.abs(seen[0][1][..., :3] - final[..., :3]).max() > 1e-3, "pass 1 is rougher"
    assert sorted(p.name for p in out_dir.iterdir()) == ["shot.exr"], "no temporary files"
    # The same image as without --progressive (both went through the same half conversion).
    np.testing.assert_array_equal(final, native.read_image(str(plain))[0])


def test_progressive_flag_and_help() -> None:
    parser = record.build_parser()
    args = parser.parse_args(["in.usda", "out.exr", "--progressive", "--samples", "4"])
    assert record.render_settings(args)["progressive"] == 1
    assert "progressive" not in record.render_settings(parser.parse_args(["in.usda", "o.exr"]))
    text = parser.format_help()
    assert "--progressive" in text and "temporary file" in text
    assert record.pass_samples(1) == [1]
    assert record.pass_samples(5) == [1, 2, 4, 5]
    assert record.pass_samples(16) == [1, 2, 4, 8, 16]


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_shows_the_pass() -> None:
    stream = Terminal()
    bar = record._Progress(stream, 1)
    bar.start(1, Usd.TimeCode(1.0), record.pass_samples(8))
    bar.update(40, 800)
    assert "pass 1/4 (1 spp)" in stream.getvalue().rsplit("\r", 1)[-1]
    bar.pass_finished(1)
    assert "pass 2/4 (2 spp)" in stream.getvalue().rsplit("\r", 1)[-1]
    bar.pass_finished(4)
    bar.update(600, 800)
    line = stream.getvalue().rsplit("\r", 1)[-1]
    assert "pass 4/4 (8 spp)" in line and " 75%" in line
    plain = Terminal()
    one = record._Progress(plain, 1)
    one.start(1, Usd.TimeCode(1.0))
    one.update(1, 2)
    assert "pass" not in plain.getvalue()


def test_session_passes_on_update_through_the_protocol(fake_native, tmp_path: Path) -> None:
    from fake_delegate import FakeRenderDelegate

    fake = FakeRenderDelegate()
    updates = Updates()
    with mipray.RenderSession(stage_with_soft_shadows(), delegate=fake) as session:
        session.render(width=8, settings={"samples": 4}, progressive=True, on_update=updates)
    assert fake.renders[-1]["settings"] == {"samples": 4, "progressive": 1}
    assert [(s, c) for s, c, _ in updates.calls] == [(1, False), (2, False), (4, True)]
