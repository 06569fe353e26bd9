"""The demo (README's run command), on fewer arrays than its default to stay short, run
as a user runs it: in a terminal, progress bars on."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

import pytest

from calibproj.cli.main import main

TERMINAL_ROWS, TERMINAL_COLUMNS = 40, 120
DEMO_TIMEOUT_S = 900.0
# A bar's last drawing: "camera far1: 100%|####| 368/368 [00:03<00:00, 106.86frame/s]".
BAR = re.compile(r"(?:camera|render) (\S+): +(\d+)%\|.*?\| (\d+)/(\d+) \[")


def run_in_terminal(args: list[str], cwd: Path) -> tuple[int, str]:
    """``python -m calibproj ARGS`` in a pseudo-terminal of 40x120; (status, what it showed)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", TERMINAL_ROWS, TERMINAL_COLUMNS, 0, 0))
    process = subprocess.Popen([sys.executable, "-m", "calibproj", *args], stdin=slave, stdout=slave,
                               stderr=slave, cwd=cwd, close_fds=True)
    os.close(slave)
    shown = bytearray()
    deadline = time.monotonic() + DEMO_TIMEOUT_S
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 1.0)
            if not ready:
                continue
            try:
                chunk = os.read(master, 1 << 16)
            except OSError:  # the terminal closed: the program ended
                break
            if not chunk:
                break
            shown += chunk
        status = process.wait(timeout=10.0)
    finally:
        process.kill()
        os.close(master)
    return status, shown.decode("utf-8", errors="replace")


def test_demo_in_a_terminal_names_final_paths_and_ends_with_the_summary(tmp_path: Path) -> None:
    status, shown = run_in_terminal(["demo", "--out", "demo", "--arrays", "12"], tmp_path)
    assert status == 0, shown[-3000:]
    out = tmp_path / "demo"
    # No message names the staging folders the run wrote into.
    assert ".tmp-" not in shown
    lines = [line.strip() for line in re.split(r"[\r\n]+", re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", shown))]
    lines = [line for line in lines if line]
    # Each bar ends complete: a camera's bar is closed when its own work ends.
    last: dict[str, tuple[int, int, int]] = {}
    for line in lines:
        match = BAR.search(line)
        if match:
            last[f"{line.split()[0]} {match.group(1)}"] = tuple(int(match.group(k)) for k in (2, 3, 4))
    cameras = ("ceiling", "far1", "far2", "far4", "far5", "near1")
    assert {f"{kind} {name}" for kind in ("camera", "render") for name in cameras} <= set(last)
    assert all(percent == 100 and done == total for percent, done, total in last.values()), last
    # Every camera compared with the truth, evaluated on independent points.
    assert "registered 6 camera(s); missing: none" in lines
    assert "success: 100 % under 0.5 px, 100 % under 2 px, 100 % under 5 px (6 cameras)" in lines
    rmse = next(line for line in lines if line.startswith("RMSE")).split()
    assert float(rmse[1]) < 0.05 and float(rmse[2]) < 2.0  # degrees, millimetres
    # It ends with the summary: each camera's status, the weak zoomed camera flagged
    # with its sigma and what helps, and where the results and the report are.
    summary = lines[lines.index("The calibration:"):]
    assert summary[-2:] == ["results: demo/results (in metres)", "report: demo/results/report.html"]
    # What the calibration's uncertainty means in millimetres (uncertainty.json).
    assert re.fullmatch(r"expected 3D error \(1 sigma\): [0-9.]+ mm at the table above the projection's centre, "
                        r"[0-9.]+ mm median over the working volume", summary[-3])
    rows = {line.split()[0]: line.split() for line in summary[1:] if line.split()[0] in cameras}
    # The reference is the first camera registered: one of them, whichever pair starts.
    statuses = sorted(rows[name][1] for name in ("far1", "far2", "far4", "far5", "near1"))
    assert statuses == ["ok"] * 4 + ["reference"], statuses
    assert rows["ceiling"][1] == "WEAK" and rows["ceiling"][3] == "deg"
    assert float(rows["ceiling"][2]) > 0.05 and rows["ceiling"][5] == "mm"
    assert "more help: calibproj generate --densify demo/results --out DENSE" in shown
    for name in ("results/report.html", "results/camera_poses.json", "room/eval_tracks.json",
                 "sequence/sequence.json"):
        assert (out / name).is_file(), name


def test_a_second_demo_does_not_overwrite_the_first_without_force(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "demo"
    (out / "results").mkdir(parents=True)
    (out / "results" / "camera_poses.json").write_text("{}")
    assert main(["demo", "--out", str(out), "--arrays", "12", "--no-progress"]) != 0
    assert "--force" in capsys.readouterr().err
