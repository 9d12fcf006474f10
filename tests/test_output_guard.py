"""Outputs never replace a file the user made or changed (core/output_guard.py)."""
import json
import os

import pytest

from blender_manikin.core import output_guard as og


def test_only_unchanged_or_claimed_outputs_may_be_replaced(tmp_path):
    mine, ours, killed = tmp_path / "mine.json", tmp_path / "take.json", tmp_path / "take.bvh"
    mine.write_text("the user's")
    assert og.in_the_way([mine, ours, killed]) == [mine]            # absent files are never in the way
    og.claim([ours, killed])
    killed.write_text("half a file a killed run left")              # claimed, never recorded: replaceable
    ours.write_text("{}")
    og.record([ours])
    assert og.in_the_way([mine, ours, killed]) == [mine]
    with pytest.raises(og.OutputInTheWay, match=r"mine.json already exists and is not this tool's"):
        og.check_free([mine, ours])
    og.check_free([mine], overwrite=True)
    # an output edited since it was written (size or time changed) is the user's now
    st = os.stat(ours)
    ours.write_text('{"edited": true}')
    os.utime(ours, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert og.in_the_way([ours]) == [ours]
    og.record([ours])                                                # written again by the tool
    assert og.in_the_way([ours]) == []
    # a record that cannot be read counts as none: everything present is in the way
    (tmp_path / og.RECORD).write_text("not json")
    assert og.in_the_way([ours, killed]) == [ours, killed]


def test_the_record_names_each_outputs_input_and_older_entries_still_read(tmp_path):
    """Entries name the input (and person) an output came from, for the next run's names
    (``recorded_stems``); they guard their files as the older entries without it do, which
    name no input."""
    take, group, old = tmp_path / "take.json", tmp_path / "group_p1.bvh", tmp_path / "old.json"
    og.claim([take, group], sources={take: ("in/take.csv", None), group: ("in/group.npy", 1)})
    assert og.in_the_way([take, group]) == []                       # claimed, not yet written: replaceable
    assert sorted(og.recorded_stems(tmp_path, [".json", ".bvh"])) == sorted([
        (og.input_key("in/take.csv"), "take"), (og.input_key("in/group.npy", "1"), "group_p1")])
    for p in (take, group, old):
        p.write_text("{}")
    og.record([take], "in/take.csv")
    og.record([group], "in/group.npy", 1)
    record = json.loads((tmp_path / og.RECORD).read_text())
    assert record["take.json"]["input"] == os.path.abspath("in/take.csv") and "person" not in record["take.json"]
    assert record["group_p1.bvh"]["person"] == "1"
    st = os.stat(old)                                               # an older version's entries: no input
    record["old.json"] = {"mtime_ns": st.st_mtime_ns, "size": st.st_size}
    record["gone.json"] = og.PENDING
    (tmp_path / og.RECORD).write_text(json.dumps(record))
    assert og.in_the_way([take, group, old]) == []
    assert sorted(s for _, s in og.recorded_stems(tmp_path, [".json", ".bvh"])) == ["group_p1", "take"]
    take.write_text('{"edited": true}')                             # edited since: in the way, input or not
    old.write_text('{"edited": true}')
    assert og.in_the_way([take, old]) == [take, old]


_WRITER = """
import os, sys
from blender_manikin.core import output_guard as og
folder, tag, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
for i in range(n):
    p = os.path.join(folder, f"{tag}{i}.json")
    with open(p, "w") as f:
        f.write("{}")
    og.claim([p], source=os.path.join(folder, "in", f"{tag}{i}.csv"))
    og.record([p], source=os.path.join(folder, "in", f"{tag}{i}.csv"))
"""


def test_two_runs_writing_into_one_folder_at_once_lose_no_entry(tmp_path):
    # two processes (two solves, a solve beside a convert) recording outputs into one --out: each
    # record write reads, changes and writes the whole record; unlocked, one run's write dropped
    # the other's entries (those outputs then read as the user's) or failed on the temporary file
    import subprocess
    import sys
    root = os.path.dirname(os.path.dirname(os.path.abspath(og.__file__)))
    env = {**os.environ, "PYTHONPATH": os.path.dirname(root)}
    n = 150
    runs = [subprocess.Popen([sys.executable, "-c", _WRITER, str(tmp_path), tag, str(n)], env=env,
                             stderr=subprocess.PIPE, text=True) for tag in "ab"]
    errors = [r.communicate()[1] for r in runs]
    assert [r.returncode for r in runs] == [0, 0], errors
    rec = json.loads((tmp_path / og.RECORD).read_text(encoding="utf-8"))
    assert sorted(rec) == sorted(f"{t}{i}.json" for t in "ab" for i in range(n))
    assert og.in_the_way([tmp_path / name for name in rec]) == []
    assert sorted(os.listdir(tmp_path)) == sorted([*rec, og.RECORD])     # no lock or temporary file left
