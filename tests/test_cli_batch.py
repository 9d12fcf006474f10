"""The command line as a batch tool: option values checked up front, interrupted writes leave
nothing behind, SIGTERM stops a batch as Ctrl-C does, the end of a run says what it did."""
import os
import subprocess
import sys

import numpy as np
import pytest

from blender_manikin import cli

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def _subparser(name):
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if hasattr(a, "choices") and isinstance(a.choices, dict))
    return sub.choices[name]


@pytest.mark.parametrize("value", ["0", "-1"])
def test_workers_below_one_is_a_usage_error(value, capsys):
    # --workers -1 made a LocalCluster with no workers: the batch waited for ever
    with pytest.raises(SystemExit) as exc:
        cli.build_parser().parse_args(["convert", "a.csv", "--out", "o", "--workers", value])
    assert exc.value.code == 2
    assert "expected 1 or more workers" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["solve", "convert"])
def test_every_option_has_help(name):
    missing = [a.option_strings for a in _subparser(name)._actions if a.option_strings and not a.help]
    assert missing == []


@pytest.mark.parametrize("option, value, said", [
    ("--height", "-2", "expected metres from 0.5 to 2.8"),
    ("--height", "175", "(metres: 1.75 for 175 cm?)"),
    ("--height", "nan", "expected metres from 0.5 to 2.8"),
    ("--arm-span", "-0.1", "expected metres from 0 to 3"),
    ("--sole", "3", "expected metres from 0 to 0.2 (metres: 0.03 for 3 cm?)"),
    ("--sole", "0.3", "expected metres from 0 to 0.2\n"),
    ("--height", "tall", "is not a number of metres"),
])
@pytest.mark.parametrize("command", ["solve", "convert"])
def test_a_length_out_of_range_is_a_usage_error(command, option, value, said, capsys):
    """--height -2 failed each file ("calibration by measurements needs a height") and 175 (typed
    in centimetres) each file too ("stature 175.0 m is not a plausible human height"); refused up
    front now, in the panel's ranges."""
    with pytest.raises(SystemExit) as exc:
        cli.build_parser().parse_args([command, "a.csv", "--out", "o", option, value])
    assert exc.value.code == 2
    assert said in capsys.readouterr().err
    assert cli.build_parser().parse_args([command, "a.csv", "--out", "o", "--height", "1.62"]).height == 1.62


def test_infinite_fps_is_a_usage_error(tmp_path, capsys):
    code = cli.main(["solve", EXAMPLE, "--out", str(tmp_path / "o"), "--format", "json", "--fps", "inf"])
    assert code == 2
    assert "--fps must be" in capsys.readouterr().err


def test_convert_into_a_file_is_said_not_a_traceback(tmp_path, capsys):
    # it was a FileExistsError traceback (a read-only --out likewise: now "error: [Errno 30] ...")
    pytest.importorskip("distributed")
    taken = tmp_path / "notes.txt"
    taken.write_text("mine")
    code = cli.main(["convert", EXAMPLE, "--out", str(taken), "--format", "json", "--no-progress"])
    assert code == 2
    assert f"blender_manikin: error: --out {taken} is a file, not a folder" in capsys.readouterr().err
    assert taken.read_text() == "mine"


def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


@pytest.mark.parametrize("fmt", ["json", "bvh", "npz"])
def test_an_interrupted_write_leaves_no_temporary_file(fmt, tmp_path, monkeypatch):
    from blender_util import synthetic_result

    from blender_manikin.core import export_bvh, export_json, formats
    result = synthetic_result(T=4, fps=30.0)
    if fmt == "json":                       # after the header went out: a half-written file
        monkeypatch.setattr(export_json, "_pose_chunks", _interrupt)
    elif fmt == "bvh":
        def half(*args, out=None, **kwargs):
            out.write("HIERARCHY\n")
            raise KeyboardInterrupt
        monkeypatch.setattr(export_bvh, "bvh_string", half)
    else:
        def half(path, **arrays):
            with open(path, "wb") as f:
                f.write(b"PK")
            raise KeyboardInterrupt
        monkeypatch.setattr(np, "savez_compressed", half)
    with pytest.raises(KeyboardInterrupt):
        formats.WRITERS[fmt].write(str(tmp_path / f"take.{fmt}"), result, source="take.csv")
    assert os.listdir(tmp_path) == []


def test_sigterm_stops_a_batch_as_ctrl_c_does(tmp_path):
    code = ("import os, signal, sys, time\n"
            "from blender_manikin import cli\n"
            "with cli._ctrl_c() as got:\n"
            "    try:\n"
            "        os.kill(os.getpid(), signal.SIGTERM)\n"
            "        time.sleep(5)\n"
            "    except KeyboardInterrupt:\n"
            "        print('stopped', got == [signal.SIGTERM])\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, (out.returncode, out.stderr)
    assert out.stdout.strip() == "stopped True"


def test_solve_ends_with_a_summary(tmp_path, capsys):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    out = tmp_path / "out"
    code = cli.main(["solve", EXAMPLE, str(empty), "--out", str(out), "--format", "json"])
    assert code == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == f"blender_manikin: 1 converted, 1 error(s) of 2 input(s); outputs in {out}"


def test_convert_into_a_folder_it_cannot_write_is_said(tmp_path, monkeypatch, capsys):
    # a read-only --out (tried on a read-only bind mount): a PermissionError / EROFS traceback before
    pytest.importorskip("distributed")
    from blender_manikin.core import convert

    def refused(folder):
        raise PermissionError(13, "Permission denied", os.path.join(folder, ".x.part1.json"))
    monkeypatch.setattr(convert, "remove_partial_outputs", refused)
    code = cli.main(["convert", EXAMPLE, "--out", str(tmp_path / "o"), "--format", "json", "--no-progress"])
    assert code == 2
    assert "blender_manikin: error: [Errno 13] Permission denied" in capsys.readouterr().err


def test_sub_folders_solve_does_not_search_are_named(tmp_path, capsys):
    # solve FOLDER read the folder's own files only and said nothing of FOLDER/day2/take.csv
    takes = tmp_path / "takes"
    (takes / "day2").mkdir(parents=True)
    (takes / "day2" / "take.csv").write_text("")
    (takes / "out").mkdir()
    (takes / "walk.csv").write_text("")
    assert cli.expand_inputs([str(takes)]) == [str(takes / "walk.csv")]
    assert "2 sub-folder(s) not searched (day2, out)" in capsys.readouterr().err
    assert cli.expand_inputs([str(takes)], out=str(takes / "out")) == [str(takes / "walk.csv")]   # not --out
    err = capsys.readouterr().err
    assert err == (f"blender_manikin: {takes}: 1 sub-folder(s) not searched (day2): give them as inputs too, "
                   "or use convert, which searches sub-folders\n")


def test_a_link_that_leads_nowhere_is_said_so(tmp_path, capsys):
    """A symbolic link that loops, or whose target is gone, was reported as 'no such file' while
    the user could see it in the folder."""
    os.symlink(tmp_path / "b.csv", tmp_path / "a.csv")
    os.symlink(tmp_path / "a.csv", tmp_path / "b.csv")
    os.symlink(tmp_path / "moved away.csv", tmp_path / "c.csv")
    code = cli.main(["solve", str(tmp_path / "a.csv"), str(tmp_path / "c.csv"), str(tmp_path / "d.csv"),
                     "--out", str(tmp_path / "o"), "--format", "json"])
    err = capsys.readouterr().err
    assert code == 1
    assert "a.csv: a symbolic link that loops" in err
    assert "c.csv: a symbolic link to " in err and "moved away.csv', which does not exist" in err
    assert "d.csv: no such file" in err


def test_a_broken_link_in_a_solved_folder_is_named(tmp_path):
    # solve FOLDER left out a take whose link's target was gone (or that looped) without a word:
    # "1 converted, 0 error(s) of 1 input(s)"; now listed, and its solve says what the link is
    (tmp_path / "walk.csv").write_text("")
    os.symlink(tmp_path / "moved.csv", tmp_path / "gone.csv")
    os.symlink("loop.csv", tmp_path / "loop.csv")
    os.symlink(tmp_path / "moved.txt", tmp_path / "notes.txt")          # no recording's extension: left out
    assert cli.expand_inputs([str(tmp_path)]) == [str(tmp_path / n) for n in ("gone.csv", "loop.csv", "walk.csv")]


def test_options_that_do_not_apply_to_an_input_are_said_once(tmp_path, capsys):
    # --ik on a tracker recording and --model on a keypoint input did nothing and said nothing
    keypoints = os.path.join(ROOT, "examples", "example_keypoints")
    code = cli.main(["solve", EXAMPLE, keypoints, "--out", str(tmp_path / "o"), "--format", "json",
                     "--ik", "naive", "--model", "head_hands"])
    assert code == 0
    err = capsys.readouterr().err
    assert err.count("--ik naive: not used for the 1 tracker recording(s) of 2 input(s)") == 1
    assert err.count("--model head_hands: not used for the 1 keypoint input(s) of 2") == 1
    code = cli.main(["solve", EXAMPLE, keypoints, "--out", str(tmp_path / "o"), "--format", "json", "--dry-run"])
    assert code == 0 and "not used for" not in capsys.readouterr().err      # nothing given: nothing said


def test_a_dry_run_says_the_unused_options_at_its_end_and_counts_no_missing_input(tmp_path, capsys):
    # the dry run said them before its listing (a solve says them at its end), and a missing
    # file was one more "tracker recording" the option was not used for
    keypoints = os.path.join(ROOT, "examples", "example_keypoints")
    missing = str(tmp_path / "gone.csv")
    code = cli.main(["solve", EXAMPLE, missing, keypoints, "--out", str(tmp_path / "o"), "--format", "json",
                     "--ik", "naive", "--dry-run"])
    assert code == 1
    err = capsys.readouterr().err
    assert "--ik naive: not used for the 1 tracker recording(s) of 3 input(s)" in err, err
    assert err.index("--ik naive: not used") > err.index(f"ERROR {missing}"), err
