"""Progress of long work: bars on a terminal, log lines elsewhere, never both in one line."""

from __future__ import annotations

import io
import logging

import pytest

from calibproj.common.progress import PeriodicProgress, progress_bar


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_a_bar_and_a_log_file_gets_lines(caplog: pytest.LogCaptureFixture) -> None:
    bar = progress_bar(100, "camera far1", stream=Terminal())
    assert type(bar).__name__ == "tqdm"
    bar.close()
    caplog.set_level(logging.INFO, logger="calibproj.common.progress")
    lines = progress_bar(100, "camera far1", stream=io.StringIO(), interval_s=0.0)
    assert isinstance(lines, PeriodicProgress)
    lines.update(40)
    lines.update(60)
    lines.close()
    lines.close()  # once only
    messages = [r.getMessage() for r in caplog.records]
    assert messages[0].startswith("camera far1: working, 40/100 frames (40 %)")
    assert messages[-1].startswith("camera far1: done, 100/100 frames (100 %)")
    assert len(messages) == 2 and not any("\r" in m for m in messages)  # done when complete, not again


def test_lines_come_at_most_once_per_interval(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="calibproj.common.progress")
    lines = PeriodicProgress(None, "render far2", interval_s=3600.0)
    for _ in range(1000):
        lines.update()
    lines.close()
    assert [r.getMessage().split(" in ")[0] for r in caplog.records] == ["render far2: done, 1000 frames"]


def test_a_disabled_bar_writes_nothing(capsys: pytest.CaptureFixture, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO)
    bar = progress_bar(10, "quiet", enabled=False, stream=Terminal())
    bar.update(10)
    bar.close()
    assert capsys.readouterr().err == "" and not caplog.records


def test_log_lines_do_not_cut_a_bar_on_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    """The command line sends log records through tqdm.write while a bar is open: each
    record gets a line of its own, and the bar is redrawn after it."""
    from tqdm.contrib.logging import logging_redirect_tqdm

    terminal = Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    logger = logging.getLogger("calibproj.test_progress")
    handler = logging.StreamHandler()  # on sys.stderr, as logging.basicConfig makes it
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        with logging_redirect_tqdm():
            bar = progress_bar(10, "camera far1")
            bar.update(3)
            logger.warning("camera far1: a message")
            bar.update(3)
            bar.close()
    finally:
        root.removeHandler(handler)
    text = terminal.getvalue()
    # The message stands on its own line: a bar's carriage return may precede it, no bar text follows it.
    assert any(line.split("\r")[-1] == "camera far1: a message" for line in text.split("\n"))


def test_a_cameras_bar_closes_when_its_own_ingest_ends(monkeypatch: pytest.MonkeyPatch) -> None:
    """Its time and rate stay its own (a finished camera's bar used to tick on until the
    slowest camera ended), and a complete one shows every frame it decoded as done."""
    from calibproj.ingest.videos import _Progress

    terminal = Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    bars = _Progress(["ceiling", "far5"], enabled=True)
    bars.callback("ceiling")(575, 599)  # the container's count was an estimate
    bars.callback("far5")(100, 1620)
    bars.finish("ceiling", complete=True)
    ceiling = bars.bars["ceiling"]
    assert ceiling.disable and ceiling.n == ceiling.total == 575
    drawn = len(terminal.getvalue())
    assert terminal.getvalue().rsplit("camera ceiling", 1)[1].split("\r")[0].count("575/575") == 1
    bars.callback("far5")(1620, 1620)
    bars.finish("far5", complete=True)
    bars.close()  # closing again draws nothing more
    later = terminal.getvalue()[drawn:]
    assert "camera far5" in later and "camera ceiling" not in later and bars.bars["far5"].n == 1620
