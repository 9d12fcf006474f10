"""tools/gui_userdata_check.sh and tools/gui_solve_check.sh, the CI steps that drive the
operators in a real Blender window, run here with stand-ins for Blender, xvfb-run and the zip
build (no Blender needed): a Blender that never quits is stopped after GUI_CHECK_TIMEOUT_S and
the step fails, where CI waited for ever.  Needs bash and coreutils' timeout (skipped without them)."""
import os
import shutil
import signal
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

pytestmark = pytest.mark.skipif(not (shutil.which("bash") and shutil.which("timeout") and sys.platform != "win32"),
                                reason="needs bash and timeout")


def _stub(folder, name, text):
    path = folder / name
    path.write_text("#!/usr/bin/env bash\n" + text)
    path.chmod(0o755)


@pytest.mark.parametrize("script, said", [("gui_userdata_check.sh", "userdata_check: ok: started"),
                                          ("gui_solve_check.sh", None)])
def test_gui_check_stops_a_blender_that_never_quits(tmp_path, script, said):
    bin_ = tmp_path / "bin"
    bin_.mkdir()
    # build_addon.py: an empty zip where the script looks for it; anything else: this Python
    _stub(bin_, "python", f'''if [ "$1" = build_addon.py ]; then
  while [ $# -gt 0 ]; do [ "$1" = --out ] && out="$2"; shift; done
  mkdir -p "$out" && : > "$out/blender_manikin-0-linux_x64.zip"; exit 0
fi
exec "{sys.executable}" "$@"
''')
    # Blender: the installs and the preference save return; the window prints a check, then hangs
    _stub(bin_, "blender", '''for a in "$@"; do case "$a" in --command|-b) exit 0;; esac; done
echo "userdata_check: ok: started"; exec sleep 600
''')
    _stub(bin_, "xvfb-run", 'shift 3; exec "$@"\n')            # -a -s "-screen ..." COMMAND...
    env = dict(os.environ, PATH=f"{bin_}{os.pathsep}{os.environ.get('PATH', '')}", GUI_CHECK_TIMEOUT_S="2")
    proc = subprocess.Popen(["bash", os.path.join(ROOT, "tools", script)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)         # the stand-in Blender and its sleep too
        proc.communicate()
        pytest.fail(f"tools/{script} still waits for a Blender that never quits")
    assert proc.returncode != 0, out
    assert "did not finish in 2 s" in out, out
    if said:
        assert said in out, out
