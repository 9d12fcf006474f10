"""``python -m blender_manikin solve INPUT... --out DIR [options]`` (needs the bpy module); see :mod:`.cli`."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
