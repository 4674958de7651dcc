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
    with pytest.raises(RuntimeError, match="half-way"):
        with atomic_open(path) as fh:
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
