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
