"""The demo (README's run command), on fewer arrays than its default to stay short."""

from __future__ import annotations

from pathlib import Path

import pytest

from calibproj.cli import main


def test_demo_calibrates_compares_and_evaluates(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--arrays", "12", "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "registered 6 camera(s); missing: none" in printed
    assert "success: 100 % under 0.5 px" in printed
    rmse = next(line for line in printed.splitlines() if line.startswith("RMSE")).split()
    assert float(rmse[1]) < 0.05 and float(rmse[2]) < 2.0  # degrees, millimetres
    for name in ("results/report.html", "results/camera_poses.json", "room/eval_tracks.json",
                 "sequence/sequence.json"):
        assert (out / name).is_file(), name
    # A second run does not overwrite the results without --force.
    assert main(["demo", "--out", str(out), "--arrays", "12", "--no-progress"]) != 0
    assert "--force" in capsys.readouterr().err
