"""Progress: a tqdm bar on a terminal, periodic log lines otherwise, nothing when quiet."""

from __future__ import annotations

import io
import logging

from vhgen.pipeline.progress import Progress, format_eta


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_log_lines_when_not_a_terminal(caplog):
    caplog.set_level(logging.INFO, logger="vhgen.progress")
    p = Progress(240, interval=0.0, stream=io.StringIO())
    p.update(60)
    p.update(60)
    p.close()
    lines = [r.getMessage() for r in caplog.records if r.name == "vhgen.progress"]
    assert len(lines) == 2
    assert lines[0].startswith("frames 60/240 (25%), ") and "frames/s, ETA " in lines[0]
    assert lines[1].startswith("frames 120/240 (50%)")


def test_log_lines_are_periodic(caplog):
    caplog.set_level(logging.INFO, logger="vhgen.progress")
    p = Progress(100, interval=3600.0, stream=io.StringIO())
    for _ in range(99):
        p.update(1)
    assert not caplog.records  # nothing before the interval...
    p.update(1)
    # ...but the end always shows
    assert len(caplog.records) == 1 and "100/100" in caplog.records[0].getMessage()


def test_bar_on_a_terminal(caplog):
    caplog.set_level(logging.INFO, logger="vhgen.progress")
    out = _Tty()
    p = Progress(50, stream=out)
    p.update(25)
    p.close()
    text = out.getvalue()
    assert "25/50" in text and "frame" in text and "\r" in text  # redrawn in place
    assert not caplog.records


def test_quiet_shows_nothing(caplog):
    caplog.set_level(logging.INFO, logger="vhgen.progress")
    out = _Tty()
    p = Progress(10, enabled=False, stream=out, interval=0.0)
    p.update(10)
    p.close()
    assert out.getvalue() == "" and not caplog.records


def test_format_eta():
    assert format_eta(12.4) == "12s"
    assert format_eta(185) == "3m05s"
    assert format_eta(3725) == "1h02m"
    assert format_eta(-1) == "0s"
