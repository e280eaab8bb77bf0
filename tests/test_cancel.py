"""Ctrl-C cancels a render promptly, from the command line and from the Python API.

Each test runs the render in a child process (SIGINT must reach a main thread, and a test
run must not be interrupted itself), on a scene slow enough that finishing it would take far
longer than the bound: path tracing at thousands of samples per pixel. The bounds are
generous because the machine is shared and noisy; they are about "promptly" (the render
stops at its next check), not a benchmark.
"""

from __future__ import annotations

import json
import os
import pty
import re
import select
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from stages import add_camera, add_cube, add_distant_light, new_stage

#: Seconds from SIGINT to the exit: the watcher polls every 20 ms and a render thread stops at
#: its next pixel; the rest is the interpreter's exit, on a loaded machine.
BOUND_S = 4.0
SLOW = {"integrator": "path", "samples": 256, "maxDepth": 8}
#: Many small tiles, so the progress bar (every 1%) shows early, and a minute's work or more.
WIDTH = 320


def slow_scene(tmp_path: Path) -> Path:
    stage = new_stage()
    add_cube(stage, "/World/Cube", scheme="catmullClark")
    floor = [(-4.0, -0.5, -4.0), (4.0, -0.5, -4.0), (4.0, -0.5, 4.0), (-4.0, -0.5, 4.0)]
    add_cube(stage, "/World/Floor", points=floor, counts=[4], indices=[0, 3, 2, 1], scheme="none")
    add_camera(stage, "/World/Cam", eye=(1.0, 1.0, 6.0))
    add_distant_light(stage, "/World/Sun")
    path = tmp_path / "slow.usda"
    stage.GetRootLayer().Export(str(path))
    return path


def read_until(fd: int, pattern: bytes, timeout: float) -> bytes:
    """What the pty gives until ``pattern`` shows (or the child closes it, or time runs out)."""
    data = b""
    end = time.monotonic() + timeout
    while pattern not in data and time.monotonic() < end:
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            try:
                chunk = os.read(fd, 4096)
            except OSError:  # the child closed its end
                break
            if not chunk:
                break
            data += chunk
    return data


@pytest.mark.parametrize(
    ("sig", "code_wanted", "line"),
    [
        (signal.SIGINT, 130, "mipray-record: interrupted"),
        # What a render farm's scheduler or `kill` sends: the same prompt stop, 128 + 15.
        (signal.SIGTERM, 143, "mipray-record: terminated"),
    ],
    ids=["SIGINT", "SIGTERM"],
)
def test_a_signal_stops_mipray_record_promptly_with_no_image_and_one_line(
    native, tmp_path: Path, sig: signal.Signals, code_wanted: int, line: str
) -> None:
    out = tmp_path / "out" / "slow.exr"
    settings = [f"--setting={k}={v}" for k, v in SLOW.items() if k != "samples"]
    args = [
        str(slow_scene(tmp_path)),
        str(out),
        "-w",
        str(WIDTH),
        "--samples",
        str(SLOW["samples"]),
    ]
    # stderr on a terminal, so the progress bar shows when the render has started.
    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "mipray", *args, *settings],
        stdout=subprocess.PIPE,
        stderr=slave,
    )
    os.close(slave)
    try:
        before = read_until(master, b"%", timeout=120.0)
        assert b"%" in before, f"the render never started: {before!r}"
        sent = time.monotonic()
        proc.send_signal(sig)
        code = proc.wait(timeout=60)
        elapsed = time.monotonic() - sent
        after = read_until(master, b"\0", timeout=1.0)
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(master)
    print(f"mipray-record: {sig.name} to exit {elapsed:.2f} s")  # shown with pytest -s
    assert code == code_wanted, (before + after).decode(errors="replace")
    assert elapsed < BOUND_S, f"exited {elapsed:.2f} s after {sig.name}"
    assert not out.exists() and not (out.parent.exists() and any(out.parent.iterdir()))
    assert proc.stdout is not None and proc.stdout.read() == b"", "no image path printed"
    # The bar is erased; what stays is one line.
    text = re.sub(rb"\x1b\[K", b"", before + after).decode(errors="replace")
    lines = [part.strip() for part in re.split(r"[\r\n]", text) if part.strip()]
    assert lines[-1] == line, lines
    assert not any("Traceback" in line for line in lines), lines


def test_keyboard_interrupt_reaches_the_api_caller_while_the_render_runs(
    native, tmp_path: Path
) -> None:
    script = textwrap.dedent(
        f"""
        import json, os, signal, time
        import mipray
        stage = mipray.open_stage({str(slow_scene(tmp_path))!r})
        sent = []

        def progress(done, total):
            # From a render thread, once the render is under way: as a user's Ctrl-C.
            if not sent:
                sent.append(time.monotonic())
                os.kill(os.getpid(), signal.SIGINT)

        with mipray.RenderSession(stage) as session:
            try:
                session.render(width={WIDTH}, settings={SLOW!r}, progress=progress)
                outcome = "finished"
            except KeyboardInterrupt:
                outcome = "KeyboardInterrupt"
            elapsed = time.monotonic() - sent[0] if sent else None
            # The session stays usable after a cancelled render.
            again = session.render(width=8, settings={{"samples": 1}})
        print(json.dumps({{"outcome": outcome, "elapsed": elapsed, "again": again.width}}))
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.strip().splitlines()[-1])
    print(f"API: SIGINT to KeyboardInterrupt {report['elapsed']:.2f} s")  # shown with pytest -s
    assert report["outcome"] == "KeyboardInterrupt", report
    assert report["elapsed"] < BOUND_S, report
    assert report["again"] == 8
