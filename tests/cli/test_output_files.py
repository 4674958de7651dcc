"""Output files are written atomically: a run that fails half-way leaves the previous file (or none)
under the requested name, never a half-written one; an unwritable place is one OutputError line."""

from __future__ import annotations

import csv

import pytest

from flatbody_env.output import OutputError, atomic_open, save_figure, write_csv


def test_write_csv_writes_the_table_and_replaces_the_old_file(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("old\n")
    write_csv(path, ["a", "b"], [[1, 2.5], ["x", ""]])
    assert list(csv.reader(path.open())) == [["a", "b"], ["1", "2.5"], ["x", ""]]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv"]  # no temporary file left


def test_a_writer_that_fails_leaves_the_previous_file_and_no_temporary(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("previous\n")
    with pytest.raises(RuntimeError, match="half-way"), atomic_open(path) as fh:
        fh.write("a,b\n")
        raise RuntimeError("half-way")
    assert path.read_text() == "previous\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv"]


def test_save_figure_writes_a_png_and_a_missing_folder_is_one_error(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [1, 0])
    out = save_figure(fig, tmp_path / "c.png", dpi=50)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(OutputError, match="missing"):
        save_figure(fig, tmp_path / "missing" / "c.png", dpi=50)
    plt.close(fig)


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_outputs_get_the_mode_the_umask_gives(tmp_path, umask, mode):
    """Every atomic output (text, bytes, a writer given the path, a CSV, a chart) ends up 0666 & ~umask,
    as a file any program creates would; an old 0600 output is replaced by one with that mode."""
    import os
    import stat

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flatbody_env.output import atomic_path, atomic_write

    old = tmp_path / "old.txt"
    old.write_text("old\n")
    old.chmod(0o600)
    fig, ax = plt.subplots(figsize=(1, 1))
    previous = os.umask(umask)
    try:
        atomic_write(tmp_path / "a.txt", "text\n")
        atomic_write(tmp_path / "b.bin", b"\x00\x01")
        atomic_write(tmp_path / "c.rrd", lambda p: p.write_bytes(b"rrd"))
        with atomic_path(tmp_path / "d.zip") as tmp:  # a writer that replaces the temporary file with its own
            tmp.unlink()
            tmp.write_bytes(b"zip")
        write_csv(tmp_path / "e.csv", ["a"], [[1]])
        save_figure(fig, tmp_path / "f.png", dpi=20)
        atomic_write(old, "new\n")
    finally:
        os.umask(previous)
        plt.close(fig)
    modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in tmp_path.iterdir()}
    assert modes == dict.fromkeys(["a.txt", "b.bin", "c.rrd", "d.zip", "e.csv", "f.png", "old.txt"], mode), {
        k: oct(v) for k, v in modes.items()
    }


# -- the one writing door: no planted link followed, the temporary removed on any failure ---------------------------
def _writers(tmp_path):
    """Every way of writing through the door, each writing 'new' to its target."""
    from flatbody_env.output import atomic_path, atomic_write

    def through_path(p):
        with atomic_path(p) as tmp:
            tmp.write_text("new\n")

    def through_open(p):
        with atomic_open(p) as fh:
            fh.write("new\n")

    return {
        "atomic_write text": lambda p: atomic_write(p, "new\n"),
        "atomic_write bytes": lambda p: atomic_write(p, b"new\n"),
        "atomic_write writer": lambda p: atomic_write(p, lambda t: t.write_text("new\n")),
        "atomic_path": through_path,
        "atomic_open": through_open,
        "write_csv": lambda p: write_csv(p, ["new"], []),
    }


@pytest.mark.parametrize(
    "how",
    ["atomic_write text", "atomic_write bytes", "atomic_write writer", "atomic_path", "atomic_open", "write_csv"],
)
def test_a_link_planted_at_the_final_name_is_refused_not_written_through(tmp_path, how):
    import os

    victim = tmp_path / "victim.txt"
    victim.write_text("unchanged\n")
    target = tmp_path / "out.csv"
    os.symlink(victim, target)
    with pytest.raises(OutputError, match=r"cannot write .*out\.csv.*symbolic link") as info:
        _writers(tmp_path)[how](target)
    assert len(str(info.value).splitlines()) == 1
    assert victim.read_text() == "unchanged\n" and target.is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv", "victim.txt"]  # no temporary left


def test_a_link_planted_at_the_temporary_name_is_never_opened(tmp_path, monkeypatch):
    """The temporary file is created new (O_EXCL | O_NOFOLLOW): a link planted under the name drawn first is left
    alone and another name is drawn."""
    import os

    from flatbody_env import output

    victim = tmp_path / "victim.txt"
    victim.write_text("unchanged\n")
    names = iter(["deadbeef", "cafef00d"])
    monkeypatch.setattr(output.secrets, "token_hex", lambda n: next(names))
    os.symlink(victim, tmp_path / ".out.txt.deadbeef.tmp.txt")
    output.atomic_write(tmp_path / "out.txt", "new\n")
    assert (tmp_path / "out.txt").read_text() == "new\n" and victim.read_text() == "unchanged\n"


@pytest.mark.parametrize(
    "how",
    ["atomic_write text", "atomic_write bytes", "atomic_write writer", "atomic_path", "atomic_open", "write_csv"],
)
def test_a_full_disk_removes_the_temporary_and_names_the_file(tmp_path, monkeypatch, how):
    """ENOSPC in the middle of a write (simulated in os.write and in Python's file writes): one line naming the file,
    the previous file kept, no temporary left."""
    import errno
    import io
    import os
    import pathlib

    from flatbody_env import output

    target = tmp_path / "out.csv"
    target.write_text("previous\n")

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    real_fdopen = os.fdopen

    class FullFile(io.TextIOBase):  # a text file whose writes fail as on a full disk
        def __init__(self, fd, *args, **kwargs):
            self.fh = real_fdopen(fd, *args, **kwargs)

        def write(self, text):
            full()

        def close(self):
            self.fh.close()
            super().close()

    monkeypatch.setattr(output.os, "write", full)
    monkeypatch.setattr(output.os, "fdopen", FullFile)
    monkeypatch.setattr(pathlib.Path, "write_text", full)
    with pytest.raises(OutputError) as info:
        _writers(tmp_path)[how](target)
    assert str(info.value) == f"cannot write {str(target)!r}: No space left on device"
    monkeypatch.undo()
    assert target.read_text() == "previous\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]


def test_a_writer_killed_mid_write_leaves_no_truncated_file_under_the_final_name(tmp_path):
    """A checkpoint whose save dies half-way (an exception inside the writer, as a kill would stop it) leaves neither a
    truncated file under a final name nor a temporary; the model is written last, so a checkpoint is whole or absent."""
    from agents.runs import RunFolder
    from agents.train import _checkpoint_writers

    class Model:
        num_timesteps = 256

        def save(self, path):
            with open(path, "wb") as fh:
                fh.write(b"PK\x03\x04 half a zip")
            raise KeyboardInterrupt  # killed while writing

    class Env:
        def save(self, path):
            with open(path, "wb") as fh:
                fh.write(b"statistics")

    run = RunFolder(path=tmp_path)
    folder = run.checkpoint_dir
    with pytest.raises(KeyboardInterrupt):
        run.save_checkpoint(256, _checkpoint_writers(Model(), Env(), True, "ppo", None))
    assert run.checkpoints() == []  # no model under its final name: no checkpoint to resume from
    assert not any(p.name.startswith(".") for p in folder.iterdir())  # no temporary left


def test_append_line_refuses_a_link_and_appends_whole_lines(tmp_path):
    import os

    from flatbody_env.output import append_line

    append_line(tmp_path / "log.txt", "a")
    append_line(tmp_path / "log.txt", "b\n")
    assert (tmp_path / "log.txt").read_text() == "a\nb\n"
    victim = tmp_path / "victim.txt"
    victim.write_text("unchanged\n")
    os.symlink(victim, tmp_path / "link.txt")
    with pytest.raises(OutputError, match="symbolic link"):
        append_line(tmp_path / "link.txt", "x")
    assert victim.read_text() == "unchanged\n"


def test_check_output_path_refuses_a_link_naming_the_flag(tmp_path):
    import os

    from flatbody_env.output import check_output_path

    os.symlink(tmp_path / "elsewhere.json", tmp_path / "report.json")
    with pytest.raises(ValueError, match=r"^--out: .*symbolic link"):
        check_output_path("--out", tmp_path / "report.json", (".json",))
