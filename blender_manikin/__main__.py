"""``python -m blender_manikin solve INPUT... --out DIR [options]`` (needs the bpy module); see :mod:`.cli`."""
import sys

from .cli import exit_process, main

if __name__ == "__main__":
    exit_process(main(sys.argv[1:]))
