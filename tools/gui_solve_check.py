"""Blender-side half of tools/gui_solve_check.sh: the solve operators in a real Blender window.

Runs inside a windowed Blender (under Xvfb) in which the extension zip was installed and enabled:

    blender --python tools/gui_solve_check.py -- --takes DIR --state STATE.json

In Blender's own event loop, as a user's clicks run them:

1. *Solve Full Body* invoked (modal: a worker thread, progress in the status bar) on DIR's
   last take: it must finish on its own and key ``MANIKIN_body``;
2. *Solve Several Files* invoked: its file browser opens on DIR; the shell script selects every
   file (A) and confirms (Return), as a user would (again, up to three times, waiting longer, when
   the browser was confirmed before it listed the files); every take must be solved onto
   ``MANIKIN_<take>`` while the window keeps running;
3. the same again, with Esc pressed (by the shell script) once the first take is written: that
   take must stay, the one being solved must leave nothing behind and the rest must not start.

``STATE.json`` tells the shell script what to do (``"phase"``: ``browser`` = a file browser is
waiting for A and Return, ``solving`` with ``"solved"`` takes written so far, ``escape`` = press
Esc now, ``passed`` / ``failed``) and, in the end, what was found (``"checks"``).  Blender quits
after the last phase; any error quits it with status 1.
"""
import argparse
import json
import os
import sys
import time
import traceback

import bpy


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    ap = argparse.ArgumentParser()
    ap.add_argument("--takes", required=True,
                    help="a folder of recordings (the last sorted, a long one, is the single take)")
    ap.add_argument("--state", required=True)
    ap.add_argument("--timeout", type=float, default=240.0)
    return ap.parse_args(argv)


ARGS = parse_args()
TAKES = sorted(f for f in os.listdir(ARGS.takes) if f.endswith(".csv"))
STATE = {"phase": "starting", "step": 0, "solved": 0, "checks": [], "t0": time.monotonic()}


def write_state():
    out = {k: STATE[k] for k in ("phase", "step", "solved", "checks")}
    with open(ARGS.state + ".tmp", "w") as fh:
        json.dump(out, fh)
    os.replace(ARGS.state + ".tmp", ARGS.state)


def finish(ok, msg=""):
    STATE["phase"] = "passed" if ok else "failed"
    if msg:
        STATE["checks"].append(msg)
    write_state()
    print(f"gui_solve_check: {STATE['phase']}: " + "; ".join(STATE["checks"]), flush=True)
    if ok:
        bpy.ops.wm.quit_blender()
    else:
        os._exit(1)


def solve_module():
    """The add-on's operators module, wherever the extension system put it (bl_ext....)."""
    return next(m for n, m in sys.modules.items() if n.endswith("blender_manikin.operators.solve"))


def running():
    return solve_module()._ACTIVE["job"] is not None


def armatures():
    return sorted(o.name for o in bpy.data.objects if o.type == 'ARMATURE')


def clear_scene():
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    bpy.context.scene.manikin.last_report = ""


def invoke(op, **props):
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == 'VIEW_3D')
    with bpy.context.temp_override(window=window, area=area):
        return op('INVOKE_DEFAULT', **props)


def check(cond, what):
    STATE["checks"].append(("ok: " if cond else "FAILED: ") + what)
    if not cond:
        finish(False)


def phases():
    """A generator: each ``yield`` waits for the next timer tick."""
    settings = bpy.context.scene.manikin
    stems = [os.path.splitext(t)[0] for t in TAKES]

    # 1. Solve Full Body, modal
    clear_scene()
    settings.source = 'FILE'
    settings.filepath = os.path.join(ARGS.takes, TAKES[-1])
    res = invoke(bpy.ops.manikin.solve_full_body)
    check(res == {'RUNNING_MODAL'}, f"Solve Full Body invoked runs modal ({sorted(res)})")
    progress = []
    while running():
        progress.append(solve_module()._ACTIVE["job"].progress)
        yield
    check(any(0.0 < p < 1.0 for p in progress), f"progress shown while it ran ({len(progress)} ticks)")
    check(armatures() == ["MANIKIN_body"], f"Solve Full Body keyed MANIKIN_body ({armatures()})")
    check(" frames at " in settings.last_report, f"its summary: {settings.last_report[:40]!r}")

    # 2. Solve Several Files through the file browser
    for esc in (False, True):
        clear_scene()
        for attempt in range(3):
            res = invoke(bpy.ops.manikin.solve_files, directory=ARGS.takes)
            check(res == {'RUNNING_MODAL'}, "Solve Several Files opens the file browser")
            STATE["phase"], STATE["step"] = "browser", STATE["step"] + 1
            write_state()
            closed = None
            while not running():                  # until the shell script confirmed the browser
                if len(bpy.context.window_manager.windows) == 1:
                    closed = closed or time.monotonic()
                    if time.monotonic() - closed > 2.0:
                        break                     # confirmed before it listed the files: again
                yield
            if running():
                break
        check(running(), "the files chosen in the file browser are being solved")
        STATE["phase"] = "solving"
        write_state()
        while running():
            STATE["solved"] = len(armatures())
            if esc and STATE["phase"] == "solving" and armatures():
                STATE["phase"] = "escape"
                write_state()
            yield
        report = settings.last_report
        if not esc:
            want = sorted(f"MANIKIN_{s}" for s in stems)
            check(armatures() == want, f"every take solved onto its own armature ({armatures()})")
            check(report.startswith(f"{len(TAKES)} of {len(TAKES)} files solved"), f"report {report[:60]!r}")
        else:
            check(armatures() == [f"MANIKIN_{stems[0]}"], f"Esc kept the first take only ({armatures()})")
            check(report.endswith(f"cancelled (Esc), {len(TAKES) - 1} file(s) not solved"),
                  f"report {report[-60:]!r}")
            n = len(bpy.data.objects)
            t = time.monotonic()
            while time.monotonic() - t < 2.0:     # nothing written late by the dropped solve
                yield
            check(len(bpy.data.objects) == n, "nothing written after Esc")
    finish(True)


GEN = phases()


def tick():
    try:
        if time.monotonic() - STATE["t0"] > ARGS.timeout:
            finish(False, f"timed out in phase {STATE['phase']}")
        next(GEN)
        write_state()
        return 0.1
    except StopIteration:
        return None
    except Exception:
        traceback.print_exc()
        finish(False, "error in the check")


bpy.app.timers.register(tick, first_interval=1.0)
