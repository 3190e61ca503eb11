"""The one output policy (userio.outputs), as properties over random path sets (Hypothesis) and as
the rules one by one: an output is never an input (aliases through ``..``, symlinks, hard links,
side files), no file is replaced without --force unless the tool wrote it, a file that appears
during a run is kept, names from data stay inside their directory, OS errors are one line."""

import errno
import os
from pathlib import Path

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from userio.errors import InputError  # noqa: E402
from userio.files import atomic_path, remove, write_files_atomic, write_text_atomic  # noqa: E402
from userio.outputs import Outputs, is_own, safe_stem  # noqa: E402

PROPS = settings(max_examples=40, deadline=None, derandomize=True, database=None,
                 suppress_health_check=[HealthCheck.function_scoped_fixture])

INPUTS = ["log.csv", "robot.toml", "cal.json"]
USER = ["notes.md", "mine.csv"]


def _tree(root: Path) -> None:
    for name in INPUTS + USER:
        (root / name).write_text(f"original {name}\n")
    (root / "sub").mkdir()
    os.symlink("log.csv", root / "link_log.csv")          # a symlink to an input
    os.link(root / "robot.toml", root / "hard_robot.toml")  # a hard link to an input
    os.symlink("notes.md", root / "link_notes.md")


def _state(root: Path) -> dict:
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_symlink():
            out[str(p.relative_to(root))] = ("l", os.readlink(p))
        elif p.is_file():
            out[str(p.relative_to(root))] = ("f", p.read_bytes(), p.stat().st_ino)
    return out


# an output path: a name of an input, of a user file, a side file, or a new name, written any way
hostile_names = st.sampled_from(INPUTS + USER + ["log.timing.toml", "log.noise.toml", "link_log.csv",
                                                 "hard_robot.toml", "link_notes.md"])
fresh_names = st.builds(lambda d, k, e: f"{d}out{k}.{e}", st.sampled_from(["", "sub/", "deep/er/"]),
                        st.integers(0, 50), st.sampled_from(["csv", "png", "md", "json"]))
names = st.one_of(fresh_names, fresh_names, fresh_names, fresh_names, hostile_names)
spell = st.sampled_from(["{n}", "./{n}", "sub/../{n}", "{root}/{n}", "sub/./../{n}"])
WROTE: list = []                     # examples that got past the checks (benchmarks: ~half)


@PROPS
@given(outs=st.lists(st.tuples(names, spell), min_size=1, max_size=3), force=st.booleans())
def test_plans_never_write_an_input_nor_replace_without_force(tmp_path_factory, outs, force):
    root = tmp_path_factory.mktemp("policy")
    _tree(root)
    cwd = os.getcwd()
    os.chdir(root)
    try:
        before = _state(root)
        plan = Outputs(force=force)
        plan.input("LOG.csv", "log.csv", log=True)
        plan.input("--robot", "robot.toml")
        plan.input("calibration", "cal.json")
        paths = [Path(sp.format(n=n, root=root)) for n, sp in outs]
        for i, p in enumerate(paths):
            plan.file(f"--out{i}", p)
        try:
            plan.check()
        except InputError:
            assert _state(root) == before            # a refusal changes nothing
            return
        with plan.active():
            write_files_atomic([(p, f"written {i}\n") for i, p in enumerate(paths)])
        WROTE.append(1)
        after = _state(root)
        for name in INPUTS + ["hard_robot.toml", "link_log.csv"]:   # inputs: same bytes, same inode
            assert after[name] == before[name]
        assert "log.timing.toml" not in after and "log.noise.toml" not in after
        named = {os.path.normpath(root / p) for p in paths}
        for name, was in before.items():             # a user's file changes only if named, with --force
            if after.get(name) != was:
                assert force and os.path.normpath(root / name) in named, name
        for i, p in enumerate(paths):                # and every output holds what was written
            assert (root / p).read_text() == f"written {i}\n"
    finally:
        os.chdir(cwd)


@PROPS
@given(name=st.text(min_size=0, max_size=40))
def test_safe_stem_never_leaves_its_directory(name):
    s = safe_stem(name)
    assert s and "/" not in s and "\\" not in s and ".." not in s and not s.startswith(".")
    assert len(s) <= 100 and Path("d", s + ".md").parent == Path("d")


def test_scene_names_are_confined_and_do_not_take_user_files(tmp_path):
    for bad in ("../../escaped", "/etc/passwd", "..", "a/b", "", "notes"):
        plan = Outputs()
        p = plan.file_in("--out-dir", tmp_path, bad + ".md")
        assert p.parent == tmp_path and ".." not in p.name
    (tmp_path / "notes.md").write_text("mine")
    plan = Outputs()
    plan.directory("--out-dir", tmp_path)
    plan.file_in("--out-dir", tmp_path, "notes.md")
    with pytest.raises(InputError, match="notes.md exists; add --force"):
        plan.check()
    assert (tmp_path / "notes.md").read_text() == "mine"


def test_a_file_created_during_the_run_is_not_replaced(tmp_path):
    out = tmp_path / "late.csv"
    plan = Outputs()
    plan.file("--out", out)
    with plan.active():
        with pytest.raises(InputError, match="appeared during the run"):
            with atomic_path(out) as tmp:
                Path(tmp).write_text("result")
                out.write_text("the user's")                 # appears while the run is going
    assert out.read_text() == "the user's"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["late.csv"]       # no temp left


def test_a_file_created_during_the_run_is_replaced_with_force(tmp_path):
    out = tmp_path / "late.csv"
    plan = Outputs(force=True)
    plan.file("--out", out)
    with plan.active():
        with atomic_path(out) as tmp:
            Path(tmp).write_text("result")
            out.write_text("the user's")
    assert out.read_text() == "result"


def test_own_files_are_replaced_others_are_not(tmp_path):
    d = tmp_path / "out"
    for round_ in range(2):                                  # a second run replaces its own files
        plan = Outputs()
        plan.directory("--out-dir", d)
        f = plan.file_in("--out-dir", d, "log.csv")
        with plan.active():
            write_text_atomic(f, f"run {round_}\n")
        assert is_own(f) and f.read_text() == f"run {round_}\n"
    f.write_text("edited by the user\n")                     # changed since: no longer the tool's
    plan = Outputs()
    plan.directory("--out-dir", d)
    plan.file_in("--out-dir", d, "log.csv")
    with pytest.raises(InputError, match="exists; add --force"):
        plan.check()
    assert f.read_text() == "edited by the user\n"


def test_undeclared_writes_and_devices_and_directories_are_refused(tmp_path):
    plan = Outputs(force=True)
    plan.file("--out", tmp_path / "a.csv")
    with plan.active():
        with pytest.raises(InputError, match="not an output this command declared"):
            write_text_atomic(tmp_path / "b.csv", "x")
    (tmp_path / "d").mkdir()
    with pytest.raises(InputError, match="is a directory"):
        Outputs(force=True).file("--out", tmp_path / "d") or None
        p = Outputs(force=True)
        p.file("--out", tmp_path / "d")
        p.check()
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    p = Outputs(force=True)
    p.file("--out", fifo)
    with pytest.raises(InputError, match="is a fifo, not a regular file"):
        p.check()


def test_remove_only_what_may_be_replaced(tmp_path):
    f = tmp_path / "x.noise.toml"
    f.write_text("user")
    plan = Outputs()                                          # declared, but not --force
    plan.file("noise", f)
    with pytest.raises(InputError):
        with plan.active():
            remove(f)
    assert f.exists()
    plan = Outputs(force=True)
    plan.file("noise", f)
    with plan.active():
        assert remove(f)
    assert not f.exists()


@pytest.mark.parametrize("err, words", [(errno.ENOSPC, "file system is full"),
                                        (errno.EROFS, "read-only"), (errno.EACCES, "ermission")])
def test_storage_errors_are_one_input_error_naming_the_path(tmp_path, monkeypatch, err, words):
    out = tmp_path / "o.csv"

    def fail(*a, **k):
        raise OSError(err, os.strerror(err), str(out))

    with pytest.raises(InputError) as exc:
        with atomic_path(out) as tmp:
            monkeypatch.setattr(Path, "write_text", fail)
            Path(tmp).write_text("x")
    assert str(out) in str(exc.value) and words in str(exc.value)
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == []                    # the temp file is gone too


def test_full_and_read_only_file_systems_are_refused_before_the_work(tmp_path, monkeypatch):
    class V:
        f_flag, f_bavail, f_frsize = 0, 0, 4096

    monkeypatch.setattr(os, "statvfs", lambda p: V)
    plan = Outputs()
    plan.file("--out", tmp_path / "o.csv")
    with pytest.raises(InputError, match="is full"):
        plan.check()
    V.f_flag, V.f_bavail = os.ST_RDONLY, 1 << 30
    with pytest.raises(InputError, match="read-only"):
        plan.check()
