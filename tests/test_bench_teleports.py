"""benchmarks/bench_teleports.py as the README's benchmark table runs it: options, and the real
recordings it looks in named, or said missing (it ran its whole benchmark on ``--help`` and,
without ``../shared``, left the real recordings out without a word)."""
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(ROOT, "benchmarks", "bench_teleports.py")
EXAMPLE = os.path.join(ROOT, "examples", "example_recording.csv")


def _run(*args):
    return subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True, timeout=120, cwd=ROOT)


def test_help_prints_the_options_and_runs_nothing():
    out = _run("--help")
    assert out.returncode == 0 and out.stdout.startswith("usage:") and "--seeds" in out.stdout, out.stdout
    assert "| take |" not in out.stdout


def test_a_recording_given_is_looked_in():
    out = _run("--seeds", "1", EXAMPLE)
    assert out.returncode == 0, out.stderr
    assert "| take | false jumps (1 x 20 s) |" in out.stdout
    assert "example_recording.csv: 0 jumps found" in out.stdout.splitlines()[-1], out.stdout
