"""The standalone command line, `python -m hemishadow transfer MESH ...`: the solver, its
progress on stderr, Ctrl-C, and the files it writes.

Run as a user runs it (a subprocess) where the terminal, signals or the umask matter.
"""

import io
import os
import pathlib
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest

import hemishadow
from hemishadow import cli

ROOT = pathlib.Path(__file__).resolve().parents[1]
SPOT = ROOT / "tests" / "assets" / "spot.obj"           # 3,225 vertices: a second or two
BUNNY = ROOT.parent / "shared" / "data" / "bunny.obj"    # 34,834 vertices: many seconds


def run(args, **options):
    return subprocess.run([sys.executable, "-m", "hemishadow", *args], capture_output=True, text=True,
                          timeout=600, **options)


def test_transfer_uses_the_solver(tmp_path, monkeypatch):
    """The exact path (every triangle blocks every vertex) took 4 minutes on the bunny."""
    def exact(*args, **kwargs):
        raise AssertionError("the command line must not use hemishadow.transfer")

    monkeypatch.setattr(hemishadow, "transfer", exact)
    assert cli.main(["transfer", str(SPOT), "--out", str(tmp_path / "spot")]) == 0
    with np.load(tmp_path / "spot.npz") as npz:
        assert npz["transfer"].shape == (3225, 25)
        assert 0.85 < npz["ambient_occlusion"].mean() < 0.95


def test_files_get_the_usual_permissions_and_no_temporary_is_left(tmp_path):
    old = os.umask(0o027)   # inherited by the child
    try:
        result = run(["transfer", str(SPOT), "--out", str(tmp_path / "out" / "spot.ply")])
    finally:
        os.umask(old)
    assert result.returncode == 0, result.stderr
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert written == ["spot.npz", "spot.ply"]
    for name in written:
        assert (tmp_path / "out" / name).stat().st_mode & 0o777 == 0o640, name


def test_progress_is_one_line_per_ten_percent_when_not_a_terminal(tmp_path):
    result = run(["transfer", str(SPOT), "--out", str(tmp_path / "spot")])
    assert result.returncode == 0, result.stderr
    lines = result.stderr.splitlines()
    assert lines and all(line.startswith("transfer: ") and line.endswith(" %") for line in lines), lines
    percents = [int(line.split()[1]) for line in lines]
    assert percents[0] == 0 and percents[-1] == 100
    tenths = [p // 10 for p in percents]
    assert tenths == sorted(set(tenths))   # one line per 10 % band reached
    assert "\r" not in result.stderr


def test_progress_bar_redraws_in_place_on_a_terminal():
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    stream = Terminal()
    bar = cli.ProgressBar("transfer", stream, width=10)
    for fraction in (0.0, 0.42, 0.425, 1.0):
        assert bar(fraction) is True
    bar.close()
    assert stream.getvalue() == ("\rtransfer [..........]   0 %\rtransfer [####......]  42 %"
                                 "\rtransfer [##########] 100 %\n")
    bar.interrupted.set()
    assert bar(0.5) is False   # what cancels the engine


def test_ctrl_c_cancels_cleanly(tmp_path):
    if not BUNNY.is_file():
        pytest.skip(f"{BUNNY} is missing")
    process = subprocess.Popen([sys.executable, "-m", "hemishadow", "transfer", str(BUNNY), "--out",
                                str(tmp_path / "bunny")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    started = threading.Event()
    seen = []

    def watch():
        for line in process.stderr:
            seen.append(line)
            if line.startswith("transfer: ") and line != "transfer: 0 %\n":
                started.set()
        started.set()   # ended: fail at once rather than wait

    reader = threading.Thread(target=watch, daemon=True)
    reader.start()
    try:
        assert started.wait(300) and process.poll() is None, f"no progress within 300 s: {seen}"
        process.send_signal(signal.SIGINT)
        assert process.wait(60) == 130
    finally:
        process.kill()
    reader.join(10)
    stderr = "".join(seen)
    assert "hemishadow: cancelled (Ctrl-C): nothing written" in stderr
    assert "Traceback" not in stderr and "100 %" not in stderr
    assert not tmp_path.joinpath("bunny.glb").exists() and list(tmp_path.iterdir()) == []
