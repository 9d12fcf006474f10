"""Blender-side half of tools/gui_userdata_check.sh: every operator of the add-on, in a real
Blender window, checked for "nothing the user made is overwritten or lost; undo works".

    blender --python tools/gui_userdata_check.py -- --repo /repo --out DIR --result RESULT.json

Runs from a window-manager timer (undo needs a window and the event loop).  For each operator:
a snapshot of the scene as plain values (objects, their data, bones' custom properties and
constraints, actions and their keys, NLA, collections, texts, the scene's range, fps and markers,
the active object and mode, the MANIKIN settings) before it, after it, after ``ed.undo`` (must
equal before) and after ``ed.redo`` (must equal after); the user's own things (made first, with
the names the add-on's would have) are checked to survive.  Writes RESULT.json and prints one
line per check (``ok:`` / ``FAILED:``); quits when done.
"""

import argparse
import json
import os
import sys
import time
import traceback

import bpy


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    ap = argparse.ArgumentParser()
    ap.add_argument("--repo", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--result", required=True)
    return ap.parse_args(argv)


ARGS = parse_args()
CHECKS = []


def log(msg):
    print("userdata_check:", msg, flush=True)


def check(cond, what, detail=""):
    CHECKS.append({"ok": bool(cond), "what": what, "detail": detail})
    log(("ok: " if cond else "FAILED: ") + what + (f" -- {detail}" if detail and not cond else ""))
    return cond


# ---------------------------------------------------------------- snapshot -----------------------


def plain(v):
    if hasattr(v, "to_dict"):
        return {k: plain(x) for k, x in v.to_dict().items()}
    if hasattr(v, "to_list"):
        return plain(v.to_list())
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if isinstance(v, float):
        return round(v, 5)
    if isinstance(v, (int, str, bool)) or v is None:
        return v
    if hasattr(v, "name"):
        return f"<{type(v).__name__} {v.name}>"
    try:
        return [plain(x) for x in v]
    except TypeError:
        return str(v)


def props(idb):
    return {k: plain(idb[k]) for k in idb.keys()}


def nla(ad):
    if ad is None:
        return None
    return {
        "action": ad.action.name if ad.action else None,
        "tweak": ad.use_tweak_mode,
        "tracks": [
            (
                t.name,
                t.mute,
                [
                    (
                        s.name,
                        s.action.name if s.action else None,
                        round(s.frame_start, 3),
                        round(s.frame_end, 3),
                        s.blend_type,
                        round(s.influence, 3),
                    )
                    for s in t.strips
                ],
            )
            for t in ad.nla_tracks
        ],
        "drivers": sorted(f"{d.data_path}[{d.array_index}]" for d in ad.drivers),
    }


def constraints(cons):
    return [
        (
            c.name,
            c.type,
            c.mute,
            round(c.influence, 4),
            getattr(getattr(c, "target", None), "name", None),
            getattr(c, "subtarget", None),
        )
        for c in cons
    ]


def obj_snap(o):
    d = {
        "type": o.type,
        "data": o.data.name if o.data else None,
        "parent": o.parent.name if o.parent else None,
        "parent_bone": o.parent_bone,
        "matrix": [round(x, 4) for row in o.matrix_world for x in row],
        "props": props(o),
        "constraints": constraints(o.constraints),
        "anim": nla(o.animation_data),
        "hide": (o.hide_viewport, o.hide_render),
        "collections": sorted(c.name for c in o.users_collection),
        "modifiers": [(m.name, m.type) for m in o.modifiers],
    }
    if o.type == "ARMATURE":
        d["bones"] = {
            b.name: (
                b.parent.name if b.parent else None,
                [round(x, 4) for x in b.head_local],
                [round(x, 4) for x in b.tail_local],
                props(b),
                b.use_deform,
            )
            for b in o.data.bones
        }
        d["pose"] = {
            p.name: (
                props(p),
                constraints(p.constraints),
                p.rotation_mode,
                [round(x, 4) for x in p.location],
                [round(x, 4) for x in p.rotation_quaternion],
            )
            for p in o.pose.bones
        }
        d["bone_collections"] = (
            sorted(c.name for c in o.data.collections_all) if hasattr(o.data, "collections_all") else None
        )
        d["armature_props"] = props(o.data)
    return d


def action_snap(a):
    fcs = getattr(a, "fcurves", None)
    curves = {}
    if fcs is not None:
        for fc in fcs:
            k = f"{fc.data_path}[{fc.array_index}]"
            co = [0.0] * (2 * len(fc.keyframe_points))
            fc.keyframe_points.foreach_get("co", co)
            curves[k] = (len(fc.keyframe_points), round(sum(co), 4), [round(x, 4) for x in co[:6]], fc.mute)
    return {"fake": a.use_fake_user, "props": props(a), "curves": curves, "range": [round(x, 3) for x in a.frame_range]}


def settings_snap(s):
    out = {}
    for p in s.bl_rna.properties:
        if p.identifier in ("rna_type", "last_report"):
            continue
        v = getattr(s, p.identifier)
        if p.type == "POINTER":
            out[p.identifier] = (
                getattr(v, "name", None)
                if isinstance(v, bpy.types.ID)
                else (settings_snap(v) if v is not None and hasattr(v, "bl_rna") else None)
            )
        elif p.type == "COLLECTION":
            out[p.identifier] = [settings_snap(x) for x in v]
        else:
            out[p.identifier] = plain(v)
    return out


def snap():
    ctx = bpy.context
    sc = ctx.scene
    vl = ctx.view_layer
    act = vl.objects.active
    return {
        "scene": {
            "name": sc.name,
            "frame_start": sc.frame_start,
            "frame_end": sc.frame_end,
            "frame_current": sc.frame_current,
            "fps": sc.render.fps,
            "fps_base": round(sc.render.fps_base, 5),
            "preview": (sc.use_preview_range, sc.frame_preview_start, sc.frame_preview_end),
            "unit": (sc.unit_settings.system, round(sc.unit_settings.scale_length, 5)),
            "markers": sorted((m.name, m.frame) for m in sc.timeline_markers),
            "props": {k: v for k, v in props(sc).items() if k != "manikin"},
            "manikin": settings_snap(sc.manikin),
        },
        "active": act.name if act else None,
        "mode": act.mode if act else None,
        "selected": sorted(o.name for o in vl.objects if o.select_get()),
        "objects": {o.name: obj_snap(o) for o in bpy.data.objects},
        "actions": {a.name: action_snap(a) for a in bpy.data.actions},
        "collections": {
            c.name: (sorted(o.name for o in c.objects), sorted(ch.name for ch in c.children))
            for c in bpy.data.collections
        },
        "scene_children": sorted(c.name for c in sc.collection.children),
        "texts": {t.name: t.as_string() for t in bpy.data.texts},
        "armatures": sorted(a.name for a in bpy.data.armatures),
        "meshes": sorted(m.name for m in bpy.data.meshes),
        "cube": cube_verts(),
    }


def cube_verts():
    """The sum of the Cube's vertex coordinates (its edit-mode mesh flushed first), or None."""
    o = bpy.data.objects.get("Cube")
    if o is None:
        return None
    if o.mode == "EDIT":
        o.update_from_editmode()
    return round(sum(v.co.x + v.co.y + v.co.z for v in o.data.vertices), 4)


def diff(a, b, path="", out=None, limit=12):
    out = [] if out is None else out
    if len(out) >= limit:
        return out
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b), key=str):
            if k not in a:
                out.append(f"{path}/{k}: added")
            elif k not in b:
                out.append(f"{path}/{k}: removed")
            else:
                diff(a[k], b[k], f"{path}/{k}", out, limit)
            if len(out) >= limit:
                break
    elif a != b:
        sa, sb = json.dumps(a, default=str)[:160], json.dumps(b, default=str)[:160]
        out.append(f"{path}: {sa} -> {sb}")
    return out


# ---------------------------------------------------------------- context ------------------------


def override():
    win = bpy.context.window_manager.windows[0]
    area = next(a for a in win.screen.areas if a.type == "VIEW_3D")
    region = next(r for r in area.regions if r.type == "WINDOW")
    return bpy.context.temp_override(window=win, area=area, region=region, screen=win.screen)


def run_op(op, mode="EXEC_DEFAULT", **kw):
    """``op`` as a button runs it: with its undo push (a script's call has none unless asked)."""
    with override():
        return op(mode, True, **kw)


def undo():
    with override():
        return bpy.ops.ed.undo()


def redo():
    with override():
        return bpy.ops.ed.redo()


def push(msg):
    with override():
        bpy.ops.ed.undo_push(message=msg)


def select_only(name):
    with override():
        if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
    for o in bpy.context.view_layer.objects:
        o.select_set(False)
    o = bpy.data.objects[name]
    o.select_set(True)
    bpy.context.view_layer.objects.active = o


def undo_round(label, op, mode="EXEC_DEFAULT", expect=("FINISHED",), **kw):
    """Run ``op``; undo must give the scene as before, redo as after.  Returns (result, before, after)."""
    push(f"before {label}")
    before = snap()
    t0 = time.monotonic()
    res = run_op(op, mode, **kw)
    check(set(res) <= set(expect) or res & set(expect), f"{label}: ran ({sorted(res)}, {time.monotonic() - t0:.1f} s)")
    after = snap()
    return res, before, after


def modal_solve_ended(solve_mod):
    """Yield to Blender's event loop until the modal solve of ``solve_mod`` (the add-on's
    operators.solve module) has ended, 300 s at most, then once more (its last redraw)."""
    t0 = time.monotonic()
    while solve_mod._ACTIVE["job"] is not None and time.monotonic() - t0 < 300:
        yield
    yield


def undo_redo(label, before, after, known=None):
    """Ctrl+Z must give ``before``, Ctrl+Shift+Z ``after``.  known: a path prefix whose difference
    after Ctrl+Z is a known limitation, said as ``known:`` instead of failing."""
    undo()
    d = diff(before, snap())
    if known:
        for line in [x for x in d if x.startswith(known)]:
            log(
                f"known: {label}: after Ctrl+Z {line} (an unkeyed slider edit shows the curve's value again, as "
                f"after Blender's own Graph Editor Smooth Keys: rewriting a curve's keys re-evaluates its animation)"
            )
        d = [x for x in d if not x.startswith(known)]
    check(not d, f"{label}: Ctrl+Z gives the scene as before", "; ".join(d))
    redo()
    d = diff(after, snap())
    check(not d, f"{label}: Ctrl+Shift+Z gives it as after", "; ".join(d))


# ---------------------------------------------------------------- the user's things --------------


def user_scene():
    """What an animator made before using the add-on, some of it with the names ours would use."""
    sc = bpy.context.scene
    sc.render.fps = 30
    sc.frame_start, sc.frame_end = 10, 20
    sc["user_note"] = "mine"
    sc.timeline_markers.new("my marker", frame=12)
    sc.timeline_markers.new("MANIKIN: my own note", frame=500)
    mine = bpy.data.objects.new("MANIKIN_body", None)  # the solve's armature name
    mine["user_prop"] = 1.5
    sc.collection.objects.link(mine)
    coll = bpy.data.collections.new("MANIKIN_trackers")  # the tracker collection's name
    sc.collection.children.link(coll)
    e = bpy.data.objects.new("my_empty_in_trackers", None)
    coll.objects.link(e)
    a = bpy.data.actions.new("MANIKIN_live_example_recording")  # the solve's action name
    a.use_fake_user = True
    fc = a.fcurves.new("location", index=0)
    fc.keyframe_points.insert(1.0, 0.25)
    t = bpy.data.texts.new("MANIKIN_offsets_none.json")
    t.write("my own text\n")


def hand_edit(action_name):
    """An animator's edit of a solved action: the first curve's first key moved up by 0.5."""
    a = bpy.data.actions[action_name]
    fc = next(fc for fc in a.fcurves if len(fc.keyframe_points))
    kp = fc.keyframe_points[0]
    kp.co[1] += 0.5
    kp.handle_left[1] += 0.5
    kp.handle_right[1] += 0.5
    fc.update()
    return f"{fc.data_path}[{fc.array_index}]", kp.co[1]


def make_character():
    sys.path[:0] = [ARGS.repo, os.path.join(ARGS.repo, "tests")]
    import blender_util as bu

    char = bu.mixamo_style_character(name="Hero")
    char["user_char_prop"] = "hero"
    pb = char.pose.bones["mixamorig:LeftArm"]
    pb["user_bone_prop"] = 3
    c = pb.constraints.new("LIMIT_ROTATION")
    c.name = "my limit"
    c2 = char.pose.bones["mixamorig:LeftForeArm"].constraints.new("LIMIT_SCALE")
    c2.name = "MANIKIN mine"  # the user's, with our prefix
    idle = bpy.data.actions.new("Hero_idle")  # no fake user: an animator's action
    fc = idle.fcurves.new('pose.bones["mixamorig:Hips"].location', index=0)
    fc.keyframe_points.insert(1.0, 0.0)
    fc.keyframe_points.insert(10.0, 0.1)
    ad = char.animation_data_create()
    ad.action = idle
    wave = bpy.data.actions.new("Hero_wave")
    fc = wave.fcurves.new('pose.bones["mixamorig:LeftArm"].rotation_quaternion', index=1)
    fc.keyframe_points.insert(1.0, 0.2)
    tr = ad.nla_tracks.new()
    tr.name = "my track"
    tr.strips.new("wave strip", 1, wave)
    return char


def make_long_take():
    """The example recording repeated 40 times (4.7 minutes): a solve that runs for seconds."""
    sys.path[:0] = [ARGS.repo]
    import numpy as np
    from blender_manikin.core.formats import load_recording
    from blender_manikin.core.io_csv import write_csv
    from blender_manikin.core.recording import Recording, TrackerStream

    rec = load_recording(os.path.join(ARGS.repo, "examples", "example_recording.csv"))
    span = max(s.time[-1] for s in rec.streams.values()) - min(s.time[0] for s in rec.streams.values()) + 0.1
    streams = {
        d: TrackerStream(
            d,
            np.concatenate([s.time + k * span for k in range(40)]),
            np.tile(s.pos, (40, 1)),
            np.tile(s.quat, (40, 1)),
            None if s.valid is None else np.tile(s.valid, 40),
        )
        for d, s in rec.streams.items()
    }
    path = os.path.join(ARGS.out, "long_take.csv")
    write_csv(
        path, Recording(streams=streams, source="long_take.csv", metadata=dict(rec.metadata)), axes="openxr", units="m"
    )
    return path


# ---------------------------------------------------------------- the checks ---------------------


def SC():
    return bpy.context.scene


def S():
    return bpy.context.scene.manikin


def steps():
    example = os.path.join(ARGS.repo, "examples", "example_recording.csv")
    user_scene()
    push("user scene")
    yield

    # -- Solve Full Body, synchronous (as a script runs it), onto the user's names
    S().source = "FILE"
    S().filepath = example
    res, before, after = undo_round("solve_full_body (exec)", bpy.ops.manikin.solve_full_body)
    arm = S().armature.name if S().armature else None
    check(
        arm is not None
        and arm != "MANIKIN_body"
        and bpy.data.objects["MANIKIN_body"].type == "EMPTY"
        and bpy.data.objects["MANIKIN_body"]["user_prop"] == 1.5,
        f"solve: the user's object MANIKIN_body kept (armature written as {arm})",
    )
    check(
        diff(before["actions"]["MANIKIN_live_example_recording"], after["actions"]["MANIKIN_live_example_recording"])
        == [],
        "solve: the user's action MANIKIN_live_example_recording untouched",
        "; ".join(
            diff(
                before["actions"]["MANIKIN_live_example_recording"], after["actions"]["MANIKIN_live_example_recording"]
            )
        ),
    )
    check(
        after["collections"]["MANIKIN_trackers"][0] == ["my_empty_in_trackers"],
        f"solve: the user's collection MANIKIN_trackers untouched ({after['collections']['MANIKIN_trackers']})",
    )
    check(
        ("MANIKIN: my own note", 500) in after["scene"]["markers"] and ("my marker", 12) in after["scene"]["markers"],
        "solve: the user's markers kept (outside the solve's range)",
    )
    check(
        (after["scene"]["frame_start"], after["scene"]["frame_end"]) != (10, 20),
        f"solve: Set Scene Range (on by default) set the range: {after['scene']['frame_start']}-"
        f"{after['scene']['frame_end']} (documented setting)",
    )
    check(after["scene"]["fps"] == 30, f"solve: the scene's fps kept ({after['scene']['fps']})")
    check(after["texts"] == before["texts"], "solve: texts untouched")
    undo_redo("solve_full_body (exec)", before, after)
    yield
    arm = S().armature.name
    solved_action = bpy.data.objects[arm].animation_data.action.name
    log(f"armature {arm}, action {solved_action}")

    # -- hand-edit the solved action, then solve again (Reuse Armature)
    select_only(arm)
    with override():
        bpy.ops.object.mode_set(mode="OBJECT")
    key, val = hand_edit(solved_action)
    push("hand edit")
    res, before, after = undo_round("solve again (reuse armature)", bpy.ops.manikin.solve_full_body)
    new_action = bpy.data.objects[arm].animation_data.action.name
    check(
        new_action != solved_action
        and solved_action in after["actions"]
        and after["actions"][solved_action] == before["actions"][solved_action]
        and after["actions"][solved_action]["fake"],
        f"re-solve: the hand-edited {solved_action} kept as it was, fake user ({new_action} assigned)",
        "; ".join(diff(before["actions"].get(solved_action), after["actions"].get(solved_action))),
    )
    undo_redo("solve again (reuse armature)", before, after)
    yield

    # -- Solve Several Files (as its file browser's confirm runs it, synchronously here) onto a name
    # the user took: their object MANIKIN_example_recording
    mine = bpy.data.objects.new("MANIKIN_example_recording", None)
    SC().collection.objects.link(mine)
    push("user's MANIKIN_example_recording")
    res, before, after = undo_round(
        "solve_files",
        bpy.ops.manikin.solve_files,
        directory=os.path.dirname(example) + os.sep,
        files=[{"name": os.path.basename(example)}],
    )
    check(
        after["objects"]["MANIKIN_example_recording"] == before["objects"]["MANIKIN_example_recording"],
        f"solve_files: the user's object MANIKIN_example_recording kept (armature {S().armature.name})",
    )
    undo_redo("solve_files", before, after)
    yield

    # -- the modal solve (Solve Full Body invoked as the panel's button does)
    push("before modal")
    before = snap()
    res = run_op(bpy.ops.manikin.solve_full_body, "INVOKE_DEFAULT")
    check(res == {"RUNNING_MODAL"}, f"modal solve: invoked ({sorted(res)})")
    solve_mod = next(m for n, m in sys.modules.items() if n.endswith("blender_manikin.operators.solve"))
    yield from modal_solve_ended(solve_mod)
    after = snap()
    check(diff(before, after) != [], "modal solve: wrote its take")
    undo_redo("modal solve", before, after)
    yield

    # -- the modal solve of a long take, the user working while it runs (undo steps on the way)
    long_take = make_long_take()
    S().filepath = long_take
    select_only("MANIKIN_body")
    push("before modal 2")
    before = snap()
    res = run_op(bpy.ops.manikin.solve_full_body, "INVOKE_DEFAULT")
    yield
    running_then = solve_mod._ACTIVE["job"] is not None
    with override():
        bpy.ops.transform.translate("EXEC_DEFAULT", True, value=(1.0, 0.0, 0.0))
    mid = snap()
    t0 = time.monotonic()
    yield from modal_solve_ended(solve_mod)
    check(
        running_then,
        f"long modal solve: still running while the user moved an object " f"({time.monotonic() - t0:.1f} s more)",
    )
    after = snap()
    check(
        mid["objects"]["MANIKIN_body"]["matrix"] == after["objects"]["MANIKIN_body"]["matrix"],
        "long modal solve: the user's move kept by the solve",
    )
    undo()
    d1 = diff(mid, snap())
    check(
        not d1,
        "long modal solve, user moved an object meanwhile: Ctrl+Z removes the solve, keeps the move",
        "; ".join(d1),
    )
    undo()
    d2 = diff(before, snap())
    check(not d2, "... and a second Ctrl+Z undoes the move", "; ".join(d2))
    redo()
    redo()
    d = diff(after, snap())
    check(not d, "... redo twice gives the scene as after", "; ".join(d))
    yield

    # -- the same, the user pressing Ctrl+Z (undoing their move) while the solve runs
    push("before modal 3")
    before = snap()
    res = run_op(bpy.ops.manikin.solve_full_body, "INVOKE_DEFAULT")
    yield
    with override():
        bpy.ops.transform.translate("EXEC_DEFAULT", True, value=(0.0, 1.0, 0.0))
    yield
    undo()  # the move undone while solving
    running_then = solve_mod._ACTIVE["job"] is not None
    mid = snap()
    yield from modal_solve_ended(solve_mod)
    check(running_then, "long modal solve, Ctrl+Z while it runs: still running after the undo")
    after = snap()
    check(
        diff(before, after) != []
        and after["objects"]["MANIKIN_body"]["matrix"] == mid["objects"]["MANIKIN_body"]["matrix"],
        f"long modal solve, Ctrl+Z while it runs: the solve written, the move undone "
        f"({S().armature.name if S().armature else None})",
    )
    undo_redo("long modal solve, Ctrl+Z while it ran, one more", before, after)
    S().filepath = example
    yield

    # -- the long modal solve while the user edits a mesh in Edit Mode (edit-mode undo steps)
    S().filepath = long_take
    select_only("Cube")
    push("before modal 4")
    before = snap()
    run_op(bpy.ops.manikin.solve_full_body, "INVOKE_DEFAULT")
    yield
    with override():
        bpy.ops.object.mode_set("EXEC_DEFAULT", True, mode="EDIT")
        bpy.ops.mesh.select_all("EXEC_DEFAULT", True, action="SELECT")
        bpy.ops.transform.translate("EXEC_DEFAULT", True, value=(0.0, 0.0, 1.0))
    running_then = solve_mod._ACTIVE["job"] is not None
    mid = snap()
    yield from modal_solve_ended(solve_mod)
    after = snap()
    check(
        running_then and after["mode"] == "EDIT" and after["cube"] == mid["cube"],
        f"long modal solve, the user in Edit Mode on a mesh meanwhile: still in Edit Mode, the edit kept "
        f"(mode {after['mode']}, cube {mid['cube']} -> {after['cube']}, running then {running_then})",
    )
    history = []
    for k in range(1, 6):
        undo()
        now = snap()
        history.append(
            f"Ctrl+Z {k}: mode {now['mode']}, cube {now['cube']}, objects {len(now['objects'])}, "
            f"actions {len(now['actions'])}"
        )
        if not diff(before, now):
            break
    log(
        "modal solve + Edit Mode edits, Ctrl+Z one at a time: "
        + "; ".join(history)
        + f" (before: mode {before['mode']}, cube {before['cube']}, objects {len(before['objects'])}, "
        f"actions {len(before['actions'])}; after: objects {len(after['objects'])}, actions {len(after['actions'])})"
    )
    first = history[0]
    check(
        f"objects {len(before['objects'])}," in first
        and f"actions {len(before['actions'])}" in first
        and f"cube {mid['cube']}" in first,
        "long modal solve + Edit Mode: the first Ctrl+Z removes the solve and keeps the mesh edit",
        first,
    )
    check(not diff(before, snap()), "... Ctrl+Z again and again gets back to before", "; ".join(diff(before, snap())))
    with override():
        if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
    push("back to object mode")
    S().filepath = example
    yield

    arm = S().armature.name
    select_only(arm)
    push("select")

    # -- swivel tools on the live rig
    SC().frame_set(SC().frame_start + 5)
    obj = bpy.data.objects[arm]
    obj["swivel_left_arm"] = obj["swivel_left_arm"] + 0.3
    push("slider edit")
    # Blender's own Insert Keyframe, for comparison: an animated object moved by hand (not
    # keyed), keyed with I, then Ctrl+Z
    e = bpy.data.objects.new("keyed_empty", None)
    SC().collection.objects.link(e)
    e.keyframe_insert("location", frame=SC().frame_start)
    e.keyframe_insert("location", frame=SC().frame_start + 10)
    select_only("keyed_empty")
    push("keyed empty")
    bpy.data.objects["keyed_empty"].location.x += 0.7
    push("moved by hand")
    with override():
        bpy.ops.anim.keyframe_insert_by_name("EXEC_DEFAULT", True, type="Location")
    keyed = bpy.data.objects["keyed_empty"].location.x
    undo()
    log(
        f"Blender's own Insert Keyframe on an animated object moved by hand, then Ctrl+Z: x "
        f"{keyed:.3f} (keyed) -> {bpy.data.objects['keyed_empty'].location.x:.3f} after Ctrl+Z"
    )
    bpy.data.objects.remove(bpy.data.objects["keyed_empty"])
    select_only(arm)
    push("select again")
    for label, op, kw in (
        ("key_swivel", bpy.ops.manikin.key_swivel, {}),
        ("smooth_swivel", bpy.ops.manikin.smooth_swivel, {}),
        ("reset_swivel", bpy.ops.manikin.reset_swivel, {"scope": "ALL"}),
    ):
        if label != "key_swivel":
            # an unkeyed slider edit before each (Key Swivel keyed the first one)
            bpy.data.objects[arm]["swivel_right_arm"] = bpy.data.objects[arm]["swivel_right_arm"] + 0.3
            push(f"slider edit before {label}")
        log(f"{label}: unkeyed slider values before: " + ", ".join(
            f"{k} {v:.3f}" for k, v in bpy.data.objects[arm].items() if k.startswith("swivel_")))
        res, before, after = undo_round(label, op, **kw)
        check(diff(before, after) != [], f"{label}: changed something")
        # Key Swivel: Ctrl+Z gives the slider's unkeyed value back (as Blender's own Insert
        # Keyframe does above), not the curve's; Smooth / Reset rewrite whole curves and, like
        # Blender's Graph Editor Smooth Keys, show the curve's value again
        undo_redo(label, before, after, known=None if label == "key_swivel" else f"/objects/{arm}/props/swivel_")
        yield

    # -- Bake to FK (a new armature)
    res, before, after = undo_round("bake_live_rig", bpy.ops.manikin.bake_live_rig)
    gone = [k for k in before["objects"] if k not in after["objects"]]
    check(not gone, f"bake_live_rig: nothing removed ({gone})")
    undo_redo("bake_live_rig", before, after)
    yield

    # -- Make Live Rig on a plain FK solve
    S().live_rig = False
    S().reuse_armature = False
    run_op(bpy.ops.manikin.solve_full_body)
    fk = S().armature.name
    select_only(fk)
    push("fk solve")
    fk_action = bpy.data.objects[fk].animation_data.action.name
    res, before, after = undo_round("make_live_rig", bpy.ops.manikin.make_live_rig)
    check(
        fk_action in after["actions"]
        and after["actions"][fk_action]["curves"] == before["actions"][fk_action]["curves"],
        f"make_live_rig: the solve action {fk_action} kept",
    )
    undo_redo("make_live_rig", before, after)
    yield
    S().live_rig = True
    S().reuse_armature = True

    # -- Retarget onto the user's character
    select_only(arm)
    char = make_character()
    S().retarget_target = char
    S().retarget_keep_ends = True
    S().retarget_live_swivel = True
    push("character")
    res, before, after = undo_round("retarget", bpy.ops.manikin.retarget)
    hb, ha = before["objects"]["Hero"], after["objects"]["Hero"]
    check(
        "Hero_idle" in after["actions"]
        and after["actions"]["Hero_idle"]["curves"] == before["actions"]["Hero_idle"]["curves"],
        "retarget: the character's own action Hero_idle kept "
        f"(fake user {after['actions'].get('Hero_idle', {}).get('fake')})",
    )
    check(
        ha["anim"]["tracks"] == hb["anim"]["tracks"],
        "retarget: the character's NLA tracks as they were",
        f"{hb['anim']['tracks']} -> {ha['anim']['tracks']}",
    )
    check(ha["props"].get("user_char_prop") == "hero", "retarget: the character's custom property kept")
    pa, pb_ = ha["pose"]["mixamorig:LeftArm"], hb["pose"]["mixamorig:LeftArm"]
    check(pa[0] == pb_[0], "retarget: the bone's custom property kept", f"{pb_[0]} -> {pa[0]}")
    user_cons = [c for c in pa[1] if c[0] == "my limit"]
    check(
        user_cons == [c for c in pb_[1] if c[0] == "my limit"],
        "retarget: the user's bone constraint kept as it was",
        f"{pb_[1]} -> {pa[1]}",
    )
    fa = ha["pose"]["mixamorig:LeftForeArm"][1]
    check(
        [c for c in fa if c[0] == "MANIKIN mine"]
        == [c for c in hb["pose"]["mixamorig:LeftForeArm"][1] if c[0] == "MANIKIN mine"],
        "retarget: the user's constraint named 'MANIKIN mine' kept",
        f"{hb['pose']['mixamorig:LeftForeArm'][1]} -> {fa}",
    )
    undo_redo("retarget", before, after)
    yield
    # retarget a second time (a new retarget replaces the rig): the user's things again
    res, before2, after2 = undo_round("retarget again", bpy.ops.manikin.retarget)
    fa = after2["objects"]["Hero"]["pose"]["mixamorig:LeftForeArm"][1]
    check(
        any(c[0] == "MANIKIN mine" for c in fa),
        "retarget again: the user's constraint named 'MANIKIN mine' kept",
        f"{fa}",
    )
    check(
        any(c[0] == "my limit" for c in after2["objects"]["Hero"]["pose"]["mixamorig:LeftArm"][1]),
        "retarget again: 'my limit' kept",
    )
    undo_redo("retarget again", before2, after2)
    yield

    # -- Bake Character to FK
    select_only("Hero")
    push("select hero")
    res, before, after = undo_round("bake_character_swivel", bpy.ops.manikin.bake_character_swivel)
    ha = after["objects"]["Hero"]
    check(
        any(c[0] == "my limit" for c in ha["pose"]["mixamorig:LeftArm"][1]),
        "bake character: the user's constraint 'my limit' kept",
        f"{ha['pose']['mixamorig:LeftArm'][1]}",
    )
    check(
        any(c[0] == "MANIKIN mine" for c in ha["pose"]["mixamorig:LeftForeArm"][1]),
        "bake character: the user's constraint named 'MANIKIN mine' kept",
        f"{ha['pose']['mixamorig:LeftForeArm'][1]}",
    )
    check(
        ha["pose"]["mixamorig:LeftArm"][0] == before["objects"]["Hero"]["pose"]["mixamorig:LeftArm"][0],
        "bake character: the bone's custom property kept",
    )
    check(ha["anim"]["tracks"] == before["objects"]["Hero"]["anim"]["tracks"], "bake character: NLA as it was")
    undo_redo("bake_character_swivel", before, after)
    yield

    # -- bone map: Load Map (undo), Save Map (a file)
    S().retarget_map = "AUTO"
    res, before, after = undo_round("load_bone_map", bpy.ops.manikin.load_bone_map)
    undo_redo("load_bone_map", before, after)
    mine = os.path.join(ARGS.out, "my_map.json")
    with open(mine, "w") as fh:
        fh.write('{"mine": true}\n')
    res, before, after = undo_round(
        "save_bone_map", bpy.ops.manikin.save_bone_map, filepath=mine, expect=("FINISHED", "CANCELLED")
    )
    log(
        f"save_bone_map onto an existing file: {sorted(res)}; file now {open(mine).read()[:40]!r}; "
        f"check_existing (the file browser's red warning): "
        f"{bpy.ops.manikin.save_bone_map.get_rna_type().properties.get('check_existing') is not None}"
    )
    check(diff(before, after) == [], "save_bone_map: the scene unchanged", "; ".join(diff(before, after)))
    yield

    # -- exports: the scene as it was, the user's files
    for label, op, ext in (
        ("export_fbx", bpy.ops.manikin.export_fbx, ".fbx"),
        ("export_gltf", bpy.ops.manikin.export_gltf, ".glb"),
    ):
        path = os.path.join(ARGS.out, "mine" + ext)
        with open(path, "w") as fh:
            fh.write("the user's own file\n")
        res, before, after = undo_round(label, op, filepath=path, expect=("FINISHED", "CANCELLED"))
        d = diff(before, after)
        check(not d, f"{label}: the scene as it was", "; ".join(d))
        log(f"{label} onto an existing file: {sorted(res)}, size now {os.path.getsize(path)}")
        undo()
        d = diff(before, snap())
        check(not d, f"{label}: Ctrl+Z leaves the scene as before", "; ".join(d))
        redo()
        yield
    takes = os.path.join(ARGS.out, "takes")
    os.makedirs(takes, exist_ok=True)
    from_char = [a.name for a in bpy.data.actions if a.name.startswith("MANIKIN_retarget_")]
    log(f"takes on Hero: {from_char}")
    res, before, after = undo_round("export_fbx_takes", bpy.ops.manikin.export_fbx_takes, directory=takes)
    files = sorted(os.listdir(takes))
    d = diff(before, after)
    check(not d, f"export_fbx_takes: the scene as it was ({files})", "; ".join(d))
    for f in files:
        with open(os.path.join(takes, f), "w") as fh:
            fh.write("the user's own file\n")
    try:
        res = run_op(bpy.ops.manikin.export_fbx_takes, directory=takes)
    except RuntimeError as exc:  # its error report, raised for a script
        res = str(exc)
    log(f"export_fbx_takes onto the user's files: {res}")
    check(
        all(open(os.path.join(takes, f)).read() == "the user's own file\n" for f in files),
        "export_fbx_takes: the user's files of those names not replaced",
    )
    yield

    # -- the small tools
    log(f"offsets preset {S().offsets_preset!r}")
    res, before, after = undo_round(
        "load_offsets_preset", bpy.ops.manikin.load_offsets_preset, preset="none", expect=("FINISHED", "CANCELLED")
    )
    check(
        after["texts"].get("MANIKIN_offsets_none.json") == "my own text\n",
        f"load_offsets_preset: the user's text MANIKIN_offsets_none.json kept ({sorted(after['texts'])})",
    )
    undo_redo("load_offsets_preset", before, after)
    yield
    res, before, after = undo_round("find_tpose", bpy.ops.manikin.find_tpose)
    undo_redo("find_tpose", before, after)
    yield
    hmd = bpy.data.objects.new("HMD", None)
    SC().collection.objects.link(hmd)
    hmd.keyframe_insert("location", frame=1)
    push("hmd")
    res, before, after = undo_round("map_devices", bpy.ops.manikin.map_devices)
    undo_redo("map_devices", before, after)
    yield


def main():
    gen = steps()

    def tick():
        try:
            next(gen)
        except StopIteration:
            done(None)
            return None
        except Exception:
            done(traceback.format_exc())
            return None
        return 0.2

    bpy.app.timers.register(tick, first_interval=1.0)


def done(error):
    if error:
        for line in ("ERROR:\n" + error).splitlines():
            log(line)
        CHECKS.append({"ok": False, "what": "script error", "detail": error})
    with open(ARGS.result, "w") as fh:
        json.dump(CHECKS, fh, indent=1)
    failed = [c for c in CHECKS if not c["ok"]]
    log(f"{len(CHECKS) - len(failed)} ok, {len(failed)} failed")
    sys.stdout.flush()
    os._exit(0)


main()
