# Sourced (from the repository root, inside the Debian 13 root) by the checks that run a real
# Blender window: tools/panel_screenshot.sh and tools/gui_solve_check.sh.  Makes a fresh Blender
# user directory under $WORK (a temporary folder, removed on exit), builds the linux-x64
# extension zip, installs and enables it with Blender's own installer, and turns the splash
# screen off, so Blender starts as a user who installed the add-on would see it.
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
export HOME="$WORK/home" BLENDER_USER_RESOURCES="$WORK/home/resources" \
       BLENDER_USER_CONFIG="$WORK/home/config" BLENDER_USER_SCRIPTS="$WORK/home/scripts"
mkdir -p "$BLENDER_USER_RESOURCES" "$BLENDER_USER_CONFIG" "$BLENDER_USER_SCRIPTS"
python build_addon.py --platform linux-x64 --out "$WORK/dist" >/dev/null
ZIP="$(ls "$WORK"/dist/blender_manikin-*-linux_x64.zip)"
blender --command extension install-file -r user_default -e "$ZIP" >/dev/null
# No splash screen over the viewport (saved into the fresh user preferences).
blender -b --python-exit-code 1 --python-expr \
  "import bpy; bpy.context.preferences.view.show_splash = False; bpy.ops.wm.save_userpref()" >/dev/null
