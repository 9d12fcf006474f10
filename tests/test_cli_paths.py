"""Paths on the command line as users type them: ``~`` that the shell did not expand (quoted,
or from a launcher / Windows shortcut), and a file whose name starts with ``-``."""

from blender_manikin import cli
from fixtures_recordings import write_recording_csv


def test_tilde_in_out_and_inputs_is_the_home_folder(tmp_path, monkeypatch):
    home, work = tmp_path / "home", tmp_path / "work"
    (home / "in").mkdir(parents=True)
    work.mkdir()
    write_recording_csv(home / "in", "take.csv", duration=2.0)
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setenv("USERPROFILE", str(home))
    monkeypatch.chdir(work)
    assert cli.main(["solve", "~/in/take.csv", "--out", "~/out", "--format", "json"]) == 0
    assert (home / "out" / "take.json").is_file()
    assert not (work / "~").exists()          # no folder named '~' made in the working directory


def test_a_file_named_with_a_leading_dash(tmp_path, monkeypatch, capsys):
    write_recording_csv(tmp_path, "-take.csv", duration=2.0)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["solve", "-take.csv", "--out", "o", "--format", "json"]) == 2
    err = capsys.readouterr().err
    assert "'-take.csv' is a file, read as an option: put -- before it" in err
    assert cli.main(["solve", "--out", "o", "--format", "json", "--", "-take.csv"]) == 0
    assert (tmp_path / "o" / "-take.json").is_file()


def test_the_same_file_given_twice_is_solved_once(tmp_path, monkeypatch, capsys):
    """``take.csv``, ``./take.csv``, its folder and a symbolic link to it: one solve, one output
    (it was solved three times over, ``OK`` printed for each)."""
    (tmp_path / "in").mkdir()
    write_recording_csv(tmp_path / "in", "take.csv", duration=2.0)
    (tmp_path / "link.csv").symlink_to(tmp_path / "in" / "take.csv")
    monkeypatch.chdir(tmp_path)
    args = ["in/take.csv", "./in/take.csv", "in", "link.csv"]
    assert cli.main(["solve", *args, "--out", "o", "--format", "json"]) == 0
    out = capsys.readouterr().out
    assert out.count("OK ") == 1, out
    assert sorted(p.name for p in (tmp_path / "o").iterdir() if not p.name.startswith(".")) == ["take.json"]
