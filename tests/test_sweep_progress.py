"""`sweep` and `compare` show a point-by-point progress bar with the time left on a terminal, and
nothing with --json or when stderr is not a terminal."""

import io
import sys

import torquebench.sweep as S


class _Tty(io.StringIO):
    def isatty(self):
        return True


def _fake_point(scene_path, overrides, outputs, cache_dir):
    return {"point": overrides, "result": {}}


def test_progress_bar_on_a_terminal_only(monkeypatch):
    monkeypatch.setattr(S, "run_point", _fake_point)
    for progress, tty, shown in ((True, True, True), (True, False, False), (False, True, False)):
        err = _Tty() if tty else io.StringIO()
        monkeypatch.setattr(sys, "stderr", err)
        rows = S.run_sweep("scene.toml", [("poke.1.alpha", [0.2, 0.5, 0.8])], executor="local",
                           progress=progress)
        assert [r["point"]["poke.1.alpha"] for r in rows] == [0.2, 0.5, 0.8]
        assert ("3/3" in err.getvalue()) == shown, (progress, tty, err.getvalue())
