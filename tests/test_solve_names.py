"""``solve``'s output names do not depend on which other inputs share the batch: an input written
into ``--out`` before keeps its outputs' names (the folder's record says which input each came
from), a new one never takes another's; ``--dry-run`` shows the names and writes nothing."""
import json
import os

from blender_manikin import cli
from blender_manikin.core import output_guard
from blender_manikin.core.file_names import short_hash
from blender_manikin.core.output_guard import RECORD

from blender_util import synthetic_result, write_recording_csv


def _takes(tmp_path):
    """``a/take.csv`` and ``b/take.csv``: two recordings sharing a name."""
    paths = []
    for k, sub in enumerate("ab"):
        (tmp_path / sub).mkdir()
        paths.append(write_recording_csv(tmp_path / sub / "take.csv", synthetic_result(T=20, fps=30.0, seed=k)))
    return paths


def _solve(out, *inputs, extra=()):
    return cli.main(["solve", *map(str, inputs), "--out", str(out), "--format", "json", *extra])


def _outputs(out):
    return sorted(n for n in os.listdir(out) if n != RECORD)


def _hashed(path):
    return f"take-{short_hash(os.path.abspath(path))}.json"


def test_an_input_written_alone_keeps_its_name_in_a_later_batch(tmp_path, capsys):
    a, b = _takes(tmp_path)
    out = tmp_path / "o"
    assert _solve(out, a) == 0
    assert _outputs(out) == ["take.json"]
    assert _solve(out, a, b) == 0
    # a keeps take.json (written again, not left stale beside a new take-<hash>.json); b gets its own
    assert _outputs(out) == sorted(["take.json", _hashed(b)])
    said = capsys.readouterr().out
    assert f"OK {a} -> {out / 'take.json'}" in said and f"OK {b} -> {out / _hashed(b)}" in said
    assert _solve(out, b) == 0 and _solve(out, a) == 0               # and alone again: the same names
    assert _outputs(out) == sorted(["take.json", _hashed(b)])


def test_inputs_written_together_keep_their_names_alone(tmp_path):
    a, b = _takes(tmp_path)
    out = tmp_path / "o"
    assert _solve(out, a, b) == 0
    assert _outputs(out) == sorted([_hashed(a), _hashed(b)])
    before = (out / _hashed(a)).stat().st_mtime_ns
    assert _solve(out, a) == 0
    assert _outputs(out) == sorted([_hashed(a), _hashed(b)])         # no take.json beside take-<hash>.json
    assert (out / _hashed(a)).stat().st_mtime_ns != before            # written again, under its name


def test_a_recorded_input_moved_on_disk_is_a_new_input(tmp_path):
    """The record knows inputs by their path: ``a/take.csv`` moved to ``b/take.csv`` is a new
    input, named apart from ``take.json`` (still ``a/take.csv``'s output), which is left as it was."""
    a, _ = _takes(tmp_path)
    os.remove(tmp_path / "b" / "take.csv")
    out = tmp_path / "o"
    assert _solve(out, a) == 0
    kept = (out / "take.json").read_bytes()
    moved = tmp_path / "b" / "take.csv"
    os.rename(a, moved)
    assert _solve(out, moved) == 0
    assert _outputs(out) == sorted(["take.json", _hashed(moved)])
    assert (out / "take.json").read_bytes() == kept
    record = json.loads((out / RECORD).read_text())
    assert record["take.json"]["input"] == str(a) and record[_hashed(moved)]["input"] == str(moved)


def test_an_older_record_without_inputs_still_reads(tmp_path):
    """A folder an earlier version wrote: its record's entries name no input (``{"size",
    "mtime_ns"}``, or ``"being written"``).  They still guard their files; a rerun replaces the
    unchanged ones, as before, and records their input, so a later batch keeps the name."""
    a, b = _takes(tmp_path)
    out = tmp_path / "o"
    assert _solve(out, a) == 0
    st = os.stat(out / "take.json")
    (out / "take.bvh").write_text("half a file a killed run left\n")
    (out / RECORD).write_text(json.dumps({"take.json": {"mtime_ns": st.st_mtime_ns, "size": st.st_size},
                                          "take.bvh": output_guard.PENDING}))
    assert output_guard.in_the_way([out / "take.json", out / "take.bvh"]) == []
    assert _solve(out, a, extra=["--format", "json,bvh"]) == 0
    record = json.loads((out / RECORD).read_text())
    assert record["take.json"]["input"] == record["take.bvh"]["input"] == str(a)
    assert _solve(out, a, b) == 0
    assert _outputs(out) == sorted(["take.bvh", "take.json", _hashed(b)])


def test_dry_run_prints_the_names_and_writes_nothing(tmp_path, capsys):
    a, b = _takes(tmp_path)
    out = tmp_path / "o"
    assert _solve(out, a, b, extra=["--dry-run"]) == 0
    assert not out.exists()                                            # not even the folder
    said = capsys.readouterr().out.splitlines()
    assert said == [f"{a} -> {out / _hashed(a)}", f"{b} -> {out / _hashed(b)}"]
    assert _solve(out, a) == 0
    capsys.readouterr()
    record = (out / RECORD).read_bytes()
    assert _solve(out, b, a, extra=["--dry-run", "--format", "json,bvh"]) == 0
    said = capsys.readouterr().out.splitlines()
    assert said == [f"{b} -> {out / _hashed(b)}, {out / _hashed(b)[:-5]}.bvh",
                    f"{a} -> {out / 'take.json'}, {out / 'take.bvh'}"]
    assert _outputs(out) == ["take.json"] and (out / RECORD).read_bytes() == record
    (out / "take.json").write_text("{}")                               # the user's edit: in the way
    assert _solve(out, a, b, extra=["--dry-run"]) == 1
    cap = capsys.readouterr()
    assert f"ERROR {a}: {out / 'take.json'} already exists" in cap.err
    assert cap.out.splitlines() == [f"{b} -> {out / _hashed(b)}"]
    assert _outputs(out) == ["take.json"] and (out / RECORD).read_bytes() == record
    assert (out / "take.json").read_text() == "{}"


def test_a_hand_edited_record_never_names_an_output_outside_out(tmp_path, capsys):
    # the record's names are file names in --out; one edited by hand to hold a folder
    # (../elsewhere.json, sub/take.json) named the input's outputs outside --out (or in a sub-folder)
    a, _ = _takes(tmp_path)
    out = tmp_path / "o"
    out.mkdir()
    entry = {"input": os.path.abspath(a), "size": 1, "mtime_ns": 1}
    (out / RECORD).write_text(json.dumps({"../elsewhere.json": entry, "sub/take.json": entry,
                                          "..\\\\win.json": entry}), encoding="utf-8")
    assert _solve(out, a, extra=["--dry-run"]) == 0
    assert capsys.readouterr().out.strip() == f"{a} -> {out / 'take.json'}"
    assert _solve(out, a) == 0
    assert _outputs(out) == ["take.json"] and not (tmp_path / "elsewhere.json").exists()
