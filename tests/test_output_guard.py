"""Outputs never replace a file the user made or changed (core/output_guard.py)."""
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
