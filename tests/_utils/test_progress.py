"""Progress bars: on a terminal only, unless asked for or against."""

from __future__ import annotations

import io
import sys

from o3d_rpointhop._utils.progress import progress_bar


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_bars_only_where_someone_watches(monkeypatch):
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # a pipe or a log file
    assert progress_bar(10, desc="x", unit="it", enabled=None) is None
    forced = progress_bar(10, desc="x", unit="it", enabled=True)
    assert forced is not None
    forced.close()
    monkeypatch.setattr(sys, "stderr", Terminal())
    shown = progress_bar(10, desc="x", unit="it", enabled=None)
    assert shown is not None
    shown.update(3)
    shown.close()
    assert "0/10" in sys.stderr.getvalue()  # drawn on the terminal
    assert progress_bar(10, desc="x", unit="it", enabled=None, large=False) is None
    assert progress_bar(10, desc="x", unit="it", enabled=False) is None
