"""Keypoint files with several people: 4-D arrays, a CSV with a person column, the person
setting, each person solved as their own one-person file would be, outputs per person."""
import json
import os

import numpy as np
import pytest

from blender_manikin import cli
from blender_manikin.core import keypoint_layouts as kl
from blender_manikin.core.io_keypoints import read_keypoint_people, read_keypoints
from blender_manikin.core.recording import RecordingError
from blender_manikin.core.solve import SolveSettings, solve_recording

from fixtures_keypoints import hinge_motion, to_y_up, write_layout_csv

FPS = 30.0
T = 150
LEAVES = 75          # person 1 is seen up to this frame
ENTERS = 30          # person 2 is seen from this frame


@pytest.fixture(scope="module")
def people():
    """``[(body, pos, world, clean keypoints (T, 17, 3) Blender axes, metres)]`` of three people
    walking apart (each a different motion, moved 1.5 m apart and drifting further)."""
    out = []
    for k in range(3):
        body, pos, world = hinge_motion(frames=T, seed=k)
        shift = np.zeros((T, 1, 3))
        shift[:, 0, 0] = 1.5 * k + 0.01 * k * np.arange(T)
        pos = pos + shift
        clean = kl.keypoints_from_body22(pos, world, "coco17", body.stature)
        out.append((body, pos, world, clean))
    return out


def _seen(k):
    """Frames where person ``k`` is seen."""
    return {0: slice(0, T), 1: slice(0, LEAVES), 2: slice(ENTERS, T)}[k]


def _stack(people):
    """``(3, T, 17, 3)`` +Y-up metres, NaN where a person is not seen."""
    X = np.full((3, T, 17, 3), np.nan)
    for k, (_, _, _, clean) in enumerate(people):
        X[k, _seen(k)] = to_y_up(clean[_seen(k)])
    return X


def _single(tmp_path, people, k):
    """Person ``k``'s frames as a one-person ``.npy``."""
    p = tmp_path / f"single{k}.npy"
    np.save(p, to_y_up(people[k][3][_seen(k)]))
    return p


def _joints(path, **kw):
    out = solve_recording(str(path), SolveSettings(fps=FPS, **kw))
    return out, out.result.fk()[0]


def test_people_first_npy_read_and_solved_per_person(tmp_path, people):
    X = _stack(people)
    ghost = np.full((1, T, 17, 3), np.nan)
    ghost[0, 10:13] = X[0, 10:13]                  # a detector's ghost: three frames
    path = tmp_path / "group.npy"
    np.save(path, np.concatenate([X, ghost]))      # (P, T, K, 3)
    got = read_keypoint_people(path)
    assert [lab for lab, _ in got] == ["0", "1", "2"]
    for lab, rec in got:
        k = int(lab)
        sl = _seen(k)
        assert rec.num_frames == sl.stop - sl.start
        assert rec.time[0] == pytest.approx(sl.start / FPS)        # the file's clock kept
        single = read_keypoints(_single(tmp_path, people, k))
        np.testing.assert_allclose(rec.points, single.points, atol=1e-9)
        np.testing.assert_allclose(rec.time - rec.time[0], single.time, atol=1e-9)
        assert "person 3 left out (seen in 3 frame(s)" in rec.metadata["detected"]
        assert rec.metadata["person"] == lab
    # one person solves as their one-person file does, at the time they were seen
    for k in (1, 2):
        out, joints = _joints(path, person=str(k))
        ref_out, ref = _joints(_single(tmp_path, people, k))
        np.testing.assert_allclose(joints, ref, atol=1e-6)
        assert out.result.t0 == pytest.approx(_seen(k).start / FPS)
        assert ref_out.result.t0 == 0.0
    with pytest.raises(RecordingError, match=r"4 people in the file \(0, 1, 2, 3\).*--person"):
        read_keypoints(path)
    with pytest.raises(RecordingError, match="person 3 left out"):
        read_keypoints(path, person=3)
    with pytest.raises(RecordingError, match="person 7: no such person"):
        read_keypoints(path, person=7)


def test_frames_first_npz_with_confidence(tmp_path, people):
    X = _stack(people)
    conf = np.isfinite(X[..., 0]).astype(np.float64)
    X = np.nan_to_num(X)                           # unseen people at zeros with confidence 0
    path = tmp_path / "group.npz"
    np.savez(path, keypoints=np.concatenate([X, conf[..., None]], -1).transpose(1, 0, 2, 3), fps=FPS)
    got = dict(read_keypoint_people(path))
    assert list(got) == ["0", "1", "2"]
    assert "3 people on axis 1 of (150, 3, 17, 4)" in got["2"].metadata["detected"]
    assert got["2"].time[0] == pytest.approx(ENTERS / FPS)
    assert got["1"].num_frames == LEAVES
    out, joints = _joints(path, person="2")
    _, ref = _joints(_single(tmp_path, people, 2))
    np.testing.assert_allclose(joints, ref, atol=1e-6)


def test_csv_with_a_track_column(tmp_path, people):
    path = tmp_path / "group.csv"
    pts = kl.LAYOUTS["coco17"].points
    with open(path, "w", encoding="utf-8") as f:
        f.write(",".join(["Time", "Track_ID"] + [f"{p}_{a}" for p in pts for a in "xyz"]) + "\n")
        for t in range(T):
            for k, (_, _, _, clean) in enumerate(people):
                s = _seen(k)
                if s.start <= t < s.stop:
                    f.write(",".join([f"{t / FPS:.6f}", f"{k + 1}"]
                                     + [f"{v:.6f}" for v in to_y_up(clean[t]).ravel()]) + "\n")
    got = dict(read_keypoint_people(path))
    assert list(got) == ["1", "2", "3"]
    assert got["3"].time[0] == pytest.approx(ENTERS / FPS)
    assert got["2"].num_frames == LEAVES
    body, pos, world, _ = people[2]
    single = tmp_path / "single.csv"
    write_layout_csv(single, "coco17", body, pos[ENTERS:], world[ENTERS:])
    np.testing.assert_allclose(got["3"].points, read_keypoints(single).points, atol=1e-5)
    _, joints = _joints(path, person="3")
    _, ref = _joints(single)
    np.testing.assert_allclose(joints, ref, atol=1e-6)
    assert read_keypoints(path, person=2).num_frames == LEAVES      # a label ("2"), not the index


def test_a_group_csv_is_parsed_a_chunk_at_a_time(tmp_path, people, monkeypatch):
    """A group CSV's rows are turned into numbers a chunk of rows at a time, not held as text
    cells all at once (a 235 MB file of 10 people took 3 GB): reading every person peaks at a
    small multiple of the file's size (12 times before), and reads what the one-chunk read does."""
    import tracemalloc
    from blender_manikin.core import recording
    path = tmp_path / "group.csv"
    pts = kl.LAYOUTS["coco17"].points
    with open(path, "w", encoding="utf-8") as f:
        f.write(",".join(["time", "person"] + [f"{p}_{a}" for p in pts for a in "xyz"]) + "\n")
        for t in range(8 * T):                  # 20 s of three people
            for k, (_, _, _, clean) in enumerate(people):
                f.write(",".join([f"{t / FPS:.6f}", str(k)] + [f"{v:.6f}" for v in to_y_up(clean[t % T]).ravel()])
                        + "\n")
    whole = read_keypoint_people(path)
    monkeypatch.setattr(recording, "CHECK_ROWS", 64)
    tracemalloc.start()
    try:
        got = read_keypoint_people(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 * os.path.getsize(path)
    assert [lab for lab, _ in got] == [lab for lab, _ in whole] == ["0", "1", "2"]
    for (_, a), (_, b) in zip(got, whole):
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.time, b.time)


def test_an_ambiguous_shape_is_refused_and_the_axis_can_be_set(tmp_path, people):
    X = _stack(people)[:, :20]
    Y = np.concatenate([X] * 4)                    # 12 people, 20 frames: too close to tell
    path = tmp_path / "square.npy"
    np.save(path, Y)
    with pytest.raises(RecordingError, match=r"square\.npy.*shape \(12, 20, 17, 3\): cannot tell the people "
                                             r"axis.*--person-axis 0"):
        read_keypoint_people(path)
    assert len(read_keypoint_people(path, person_axis=0)) == 8      # every third enters at frame 30
    np.savez(tmp_path / "square.npz", keypoints=Y, person_axis=0)
    assert len(read_keypoint_people(tmp_path / "square.npz")) == 8


def test_cli_writes_one_output_per_person_and_keeps_single_files(tmp_path, people, capsys):
    X = _stack(people)
    d = tmp_path / "in"
    d.mkdir()
    np.save(d / "group.npy", X)
    np.save(d / "solo.npy", to_y_up(people[0][3]))
    out = tmp_path / "out"
    code = cli.main(["solve", str(d), "--out", str(out), "--format", "json", "--fps", "30"])
    lines = capsys.readouterr().out.splitlines()
    assert code == 0
    assert sorted(p.name for p in out.iterdir() if p.suffix == ".json") == [
        "group_p0.json", "group_p1.json", "group_p2.json", "solo.json"]
    ok = [ln for ln in lines if ln.startswith("OK ") and "group.npy" in ln]
    assert len(ok) == 3 and all("of 3: 0, 1, 2]" in ln for ln in ok)
    doc = json.loads((out / "group_p2.json").read_text())
    assert doc["t0"] == pytest.approx(ENTERS / FPS)
    assert len(doc["positions"]) == T - ENTERS
    solo = json.loads((out / "solo.json").read_text())
    assert solo["t0"] == 0.0 and len(solo["positions"]) == T
    code = cli.main(["solve", str(d / "group.npy"), "--out", str(tmp_path / "one"), "--format", "json",
                     "--person", "1"])
    assert code == 0
    assert [p.name for p in (tmp_path / "one").iterdir() if p.suffix == ".json"] == ["group.json"]


def test_cli_reads_a_group_file_once_and_solves_each_person_from_it(tmp_path, people, monkeypatch):
    """``solve --person all``: the file is read once, each person solved from their recording
    (the outputs as when each was read on its own)."""
    from blender_manikin.core import io_keypoints
    path = tmp_path / "group.npy"
    np.save(path, _stack(people))
    loads = []
    real = io_keypoints._load_input

    def load(p, *a, **kw):
        loads.append(str(p))
        return real(p, *a, **kw)

    monkeypatch.setattr(io_keypoints, "_load_input", load)
    out = tmp_path / "out"
    assert cli.main(["solve", str(path), "--out", str(out), "--format", "json", "--fps", "30"]) == 0
    assert loads == [str(path)]
    monkeypatch.setattr(io_keypoints, "_load_input", real)
    doc = json.loads((out / "group_p2.json").read_text())
    _, ref = _joints(path, person="2")
    assert len(doc["positions"]) == len(ref) == T - ENTERS and doc["t0"] == pytest.approx(ENTERS / FPS)


def test_person_stems_fit_windows_260_characters(tmp_path):
    """Each person's stem (``<stem>_p<label>``) is cut to fit a deep folder on Windows, with a hash
    that keeps two people apart; off Windows, or where it fits, it is unchanged."""
    from blender_manikin.core.file_names import MAX_PATH, person_stems
    deep = "/" + "/".join(["folder" * 5] * 6)            # 186 characters
    long = "a_very_long_take_name_" * 4
    got = person_stems(long, ["0", "1"], key="/in/group.npy", folder=deep, tail=20, windows=True)
    assert len(set(got)) == 2 and all(len(deep) + 1 + len(s) + 20 <= MAX_PATH - 1 for s in got)
    assert all(s.startswith(long[:10]) and len(s.rsplit("-", 1)[1]) == 8 for s in got)
    assert person_stems("take", ["0", "1"], key="k", folder=deep, tail=20, windows=True) == ["take_p0", "take_p1"]
    assert person_stems(long, ["0", "a b"], folder=str(tmp_path), windows=False) == [f"{long}_p0", f"{long}_pa_b"]
    assert person_stems("take", ["x", "X"]) == ["take_px", "take_pX_2"]


def test_one_person_csv_with_a_row_id_or_a_one_value_subject_column_reads_as_before(tmp_path, people):
    """A one-person CSV with an ``id`` column numbering the rows (a value on every row: not a
    person column) or a ``subject`` column with one value (one person) is read, and solved with
    the default person ``all``, as the same file without the column (both were refused: "60
    people in the file", "1 people in the file (S01): choose one")."""
    body, pos, world, _ = people[0]
    plain = tmp_path / "plain.csv"
    write_layout_csv(plain, "coco17", body, pos, world)
    head, *rows = plain.read_text().splitlines()
    ref = read_keypoints(plain)
    for name, col, cell in (("rowid.csv", "id", lambda k: str(k)), ("subject.csv", "subject", lambda k: "S01")):
        path = tmp_path / name
        path.write_text("\n".join([f"{col},{head}"] + [f"{cell(k)},{r}" for k, r in enumerate(rows)]) + "\n")
        rec = read_keypoints(path)
        np.testing.assert_allclose(rec.points, ref.points, atol=1e-12)
        np.testing.assert_allclose(rec.time, ref.time, atol=1e-12)
        out = solve_recording(str(path), SolveSettings(fps=FPS))
        assert out.result.fk()[0].shape[0] == T
    assert "1 person (the CSV's person column)" in read_keypoints(tmp_path / "subject.csv").metadata["detected"]
    notime = tmp_path / "rowid_notime.csv"                   # no time column: the rate decides, as before
    notime.write_text("\n".join(["id," + head.split(",", 1)[1]]
                                + [f"{k},{r.split(',', 1)[1]}" for k, r in enumerate(rows)]) + "\n")
    assert read_keypoints(notime).num_frames == T


def test_a_persons_output_never_takes_another_inputs_name(tmp_path, people):
    """``group.npy`` (two people) beside a one-person ``group_p0.npy``: person 0's outputs would be
    ``group_p0.json``, the other file's name, and one was written over the other (solve and
    convert alike); person 0 now gets a hash, as inputs sharing a name do, the same in both."""
    from blender_manikin.core.file_names import short_hash
    d = tmp_path / "in"
    d.mkdir()
    np.save(d / "group.npy", _stack(people)[:2])
    np.save(d / "group_p0.npy", to_y_up(people[2][3]))
    want = f"group_p0-{short_hash(str(d / 'group.npy') + '#person=0')}.json"
    out = tmp_path / "solve"
    assert cli.main(["solve", str(d), "--out", str(out), "--format", "json", "--fps", "30"]) == 0
    outs = [out]
    try:                        # convert needs the [dask] extra (not in every test environment)
        import distributed  # noqa: F401
    except ImportError:
        pass
    else:
        from blender_manikin.core import convert
        code, _ = convert.run(convert.collect_inputs([str(d)]), str(tmp_path / "convert"), ["json"],
                              SolveSettings(fps=FPS), workers=1, progress=False, log=lambda m: None)
        assert code == 0
        outs.append(tmp_path / "convert")
    for o in outs:
        assert sorted(p.name for p in o.iterdir() if p.suffix == ".json") == sorted(
            ["group_p0.json", "group_p1.json", want])
        mine = json.loads((o / want).read_text())                      # the group's person 0, near x = 0
        other = json.loads((o / "group_p0.json").read_text())          # the other file: person 2, 3 m away
        assert len(mine["positions"]) == len(other["positions"]) == T
        assert abs(mine["positions"][0][0][0]) < 1.0 and other["positions"][0][0][0] > 2.0
        assert len(json.loads((o / "group_p1.json").read_text())["positions"]) == LEAVES


def test_one_person_file_is_told_without_reading_the_samples(tmp_path, people, monkeypatch):
    """``one_person_file`` tells a file surely holding one person from its header only (the
    Blender operators then read it in their background job): a 3-D ``.npy`` (its samples never
    loaded), a ``.trc``, a CSV without a person column; a 4-D array, a CSV with a track column,
    a ``.npz`` and a missing file are not (they are read to list their people)."""
    from blender_manikin.core import io_keypoints as ik
    body, pos, world, _ = people[0]
    single = _single(tmp_path, people, 0)
    group = tmp_path / "group.npy"
    np.save(group, _stack(people))
    plain = tmp_path / "plain.csv"
    write_layout_csv(plain, "coco17", body, pos, world)
    head, *rows = plain.read_text().splitlines()
    tracked = tmp_path / "tracked.csv"
    tracked.write_text("\n".join(["# made by a tracker", "", f"Track,{head}"] + [f"0,{r}" for r in rows]) + "\n")
    trc = tmp_path / "take.trc"
    trc.write_text("PathFileType\t4\t(X/Y/Z)\ttake.trc\n")
    np.savez(tmp_path / "one.npz", keypoints=to_y_up(people[0][3]))
    loads = []
    real_load = np.load
    monkeypatch.setattr(ik.np, "load", lambda *a, **kw: loads.append(kw.get("mmap_mode")) or real_load(*a, **kw))
    assert ik.one_person_file(single) and ik.one_person_file(str(plain)) and ik.one_person_file(trc)
    assert loads == ["r"]                                   # the .npy's header only, mapped, not read
    assert not ik.one_person_file(group) and not ik.one_person_file(tracked)
    assert not ik.one_person_file(tmp_path / "one.npz") and not ik.one_person_file(tmp_path / "missing.npy")


def test_a_device_named_group_files_people_are_named_alike_everywhere_and_old_outputs_kept(tmp_path, people):
    """``con.npy`` with two people: ``solve`` and ``convert`` write ``con_p0`` / ``con_p1`` (no longer
    ``con__p1``: the person suffix already makes a name Windows accepts), as Blender names the
    takes; a convert folder an earlier version filled with ``con__p*`` outputs keeps them: the
    changed input is converted again into the same files, no second set."""
    d = tmp_path / "in"
    d.mkdir()
    np.save(d / "con.npy", _stack(people)[:2])
    out = tmp_path / "solve"
    assert cli.main(["solve", str(d / "con.npy"), "--out", str(out), "--format", "json", "--fps", "30"]) == 0
    assert sorted(p.name for p in out.glob("*.json")) == ["con_p0.json", "con_p1.json"]
    try:                        # convert needs the [dask] extra (not in every test environment)
        import distributed  # noqa: F401
    except ImportError:
        return
    from blender_manikin.core import convert, output_guard
    conv = tmp_path / "convert"

    def run():
        code, _ = convert.run(convert.collect_inputs([str(d)]), str(conv), ["json"], SolveSettings(fps=FPS),
                              workers=1, progress=False, log=lambda m: None)
        assert code == 0
        return sorted(p.name for p in conv.glob("*.json"))
    assert run() == ["con_p0.json", "con_p1.json"]
    # the folder as the earlier version left it: con__p0/1.json in the outputs, manifest and record
    for k in "01":
        os.rename(conv / f"con_p{k}.json", conv / f"con__p{k}.json")
    man = conv / convert.MANIFEST
    man.write_text(man.read_text().replace("con_p", "con__p"))
    rec = conv / output_guard.RECORD
    rec.write_text(rec.read_text().replace("con_p", "con__p"))
    assert run() == ["con__p0.json", "con__p1.json"]            # done: nothing converted, nothing new
    st = os.stat(d / "con.npy")
    os.utime(d / "con.npy", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    before = (conv / "con__p1.json").stat().st_mtime_ns
    assert run() == ["con__p0.json", "con__p1.json"]            # converted again, into the same files
    assert (conv / "con__p1.json").stat().st_mtime_ns != before


def test_cli_reads_one_person_files_in_turn_not_all_before_the_solves(tmp_path, people, monkeypatch):
    """``solve --person all`` over several one-person keypoint files: each is read by its own
    solve when its turn comes (told one person's from its header, :func:`one_person_file`), so
    the batch never holds every file's recording at once; a group file is still read first."""
    from blender_manikin.core import io_keypoints
    from blender_manikin.core import solve as core_solve
    d = tmp_path / "in"
    d.mkdir()
    for k in (0, 1):
        np.save(d / f"solo{k}.npy", to_y_up(people[k][3][_seen(k)]))
    log = []
    real_load, real_solve = io_keypoints._load_input, core_solve.solve_recording

    def load(p, *a, **kw):
        log.append(f"read {os.path.basename(str(p))}")
        return real_load(p, *a, **kw)

    def solve(source, *a, **kw):
        log.append("solve")
        return real_solve(source, *a, **kw)

    monkeypatch.setattr(io_keypoints, "_load_input", load)
    monkeypatch.setattr(core_solve, "solve_recording", solve)
    out = tmp_path / "out"
    assert cli.main(["solve", str(d), "--out", str(out), "--format", "json", "--fps", "30"]) == 0
    assert log == ["solve", "read solo0.npy", "solve", "read solo1.npy"]
    assert sorted(p.name for p in out.iterdir() if p.suffix == ".json") == ["solo0.json", "solo1.json"]


@pytest.mark.parametrize("shape", [(2, 60, 20, 3), (2, 60, 21, 3)])
def test_a_marker_sets_joint_count_is_no_array_layout(tmp_path, shape):
    """OpenCap's 20 and Plug-in Gait's 21 points are joint centres and pelvis midpoints computed
    from named markers, never an array's points: a 4-D array of that many points is refused, and
    the message lists only the layouts an array can hold."""
    path = tmp_path / "group.npy"
    np.save(path, np.zeros(shape, np.float32))
    with pytest.raises(RecordingError) as err:
        read_keypoint_people(str(path))
    text = str(err.value)
    assert "no layout's point count" in text and "20" not in text.split("(")[-1]
    assert set(kl.array_layouts()) == set(kl.LAYOUTS) - set(kl.MARKER_LAYOUTS)


def test_an_unnamed_array_of_a_marker_sets_count_names_the_array_layouts(tmp_path):
    """The refusal of an unnamed (T, 21, 3) array lists the array layouts' counts, not the
    marker sets' (which a user cannot give as an array)."""
    path = tmp_path / "points.npy"
    np.save(path, np.zeros((60, 21, 3), np.float32))
    with pytest.raises(RecordingError) as err:
        read_keypoints(str(path))
    assert "match no keypoint layout" in str(err.value)
    assert "plugingait" not in str(err.value) and "opencap" not in str(err.value)


def test_a_group_files_people_keep_their_names_in_a_later_batch(tmp_path, people):
    """``a/group.npy`` solved alone writes ``group_p0`` / ``group_p1``; solved again beside
    ``b/group.npy`` its people keep those names (none left stale beside new ones) and ``b``'s
    people get names of their own; and so alone again."""
    from blender_manikin.core.file_names import short_hash
    groups = []
    for sub in "ab":
        (tmp_path / sub).mkdir()
        np.save(tmp_path / sub / "group.npy", _stack(people)[:2])
        groups.append(tmp_path / sub / "group.npy")
    a, b = groups
    out = tmp_path / "o"

    def solve(*inputs):
        assert cli.main(["solve", *map(str, inputs), "--out", str(out), "--format", "json", "--fps", "30"]) == 0
        return sorted(p.name for p in out.iterdir() if p.suffix == ".json")
    assert solve(a) == ["group_p0.json", "group_p1.json"]
    theirs = [f"group_p{k}-{short_hash(str(b) + f'#person={k}')}.json" for k in (0, 1)]
    assert solve(a, b) == sorted(["group_p0.json", "group_p1.json"] + theirs)
    assert solve(b) == solve(a) == sorted(["group_p0.json", "group_p1.json"] + theirs)
