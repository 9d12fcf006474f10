#!/usr/bin/env bash
# A Debian 13 (trixie) root for the Python 3.13 / numpy 2 half of the test matrix: Blender 5.1 and
# 5.2 LTS run Python 3.13, this machine (Debian 12) has only 3.11.  The root holds
#   * /opt/venv-bpy52: Python 3.13 venv with requirements-bpy52.txt (bpy 5.2.3, numpy 2.x, ...);
#   * Debian's own `blender` package (4.3.x, Python 3.13): a real Blender binary, for the
#     `blender -b --python cli.py` test and, under Xvfb, screenshots of the panels.
#
#   bash tools/debian13.sh setup            # create or update the root (cached, ~1.5 GB)
#   bash tools/debian13.sh run CMD ARGS...  # run CMD inside it, in the repository (/repo)
#
# Needs root (debootstrap, mount, chroot), as CI and the development machines have.  The root
# lives OUTSIDE the repository, in $BLENDER_MANIKIN_DEBIAN13 (default
# ~/.cache/blender_manikin/debian13), so reruns only check that it is up to date.  While a command
# runs, /proc, /sys and /dev are bind-mounted into the root, the repository at /repo, and the
# wheel cache at the same path as outside; all are unmounted afterwards, even on failure.
set -euo pipefail
REPO="$(cd "$(dirname "$0")/.." && pwd)"
ROOTFS="${BLENDER_MANIKIN_DEBIAN13:-$HOME/.cache/blender_manikin/debian13}"
WHEELS="${BLENDER_MANIKIN_WHEEL_CACHE:-$HOME/.cache/blender_manikin/wheels}"
MIRROR="${DEBIAN_MIRROR:-http://deb.debian.org/debian}"
# Debian packages inside the root: Python 3.13 venvs, Blender 4.3, and what a windowed Blender
# needs under a virtual X server (Mesa's software OpenGL) plus the screenshot tools.
PACKAGES="python3-venv ca-certificates blender python3-numpy xvfb xauth xdotool imagemagick libgl1-mesa-dri libegl1 libegl-mesa0 libgbm1"
VENV=/opt/venv-bpy52

die() { echo "tools/debian13.sh: $*" >&2; exit 1; }
[ "$(id -u)" = 0 ] || die "needs root (debootstrap, mount and chroot)"

MOUNTS=()
cleanup() {
  local i
  for ((i=${#MOUNTS[@]}-1; i>=0; i--)); do umount -R "${MOUNTS[$i]}" 2>/dev/null || umount -l "${MOUNTS[$i]}" || true; done
  MOUNTS=()
}
trap cleanup EXIT

bind() {  # bind SRC DEST_INSIDE_ROOT
  mkdir -p "$ROOTFS$2"
  mount --rbind "$1" "$ROOTFS$2"
  mount --make-rslave "$ROOTFS$2"
  MOUNTS+=("$ROOTFS$2")
}

mount_all() {
  bind /proc /proc
  bind /sys /sys
  bind /dev /dev
  bind "$REPO" /repo
  # The project's shared data (training mocap, VR samples) sits beside the repository, and the
  # tests look for it there: /shared beside /repo.
  if [ -d "$REPO/../shared" ]; then bind "$(cd "$REPO/../shared" && pwd)" /shared; fi
  mkdir -p "$WHEELS"
  bind "$WHEELS" "$WHEELS"
  # The host's certificate bundle (it may hold a proxy's CA that Debian's bundle lacks).
  cp /etc/ssl/certs/ca-certificates.crt "$ROOTFS/etc/host-ca-certificates.crt"
  cp /etc/resolv.conf "$ROOTFS/etc/resolv.conf" 2>/dev/null || true
  # Blender reads the mounted file systems from /etc/mtab (warns on stdout without it).
  [ -e "$ROOTFS/etc/mtab" ] || ln -s /proc/self/mounts "$ROOTFS/etc/mtab"
}

in_root() {  # in_root CMD...: a clean environment, no host Python or pip settings
  chroot "$ROOTFS" /usr/bin/env -i \
    PATH="$VENV/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin" \
    HOME=/root LANG=C.UTF-8 LC_ALL=C.UTF-8 DEBIAN_FRONTEND=noninteractive \
    PIP_CERT=/etc/host-ca-certificates.crt PIP_DEFAULT_TIMEOUT=180 PIP_DISABLE_PIP_VERSION_CHECK=1 \
    BLENDER_MANIKIN_WHEEL_CACHE="$WHEELS" CI="${CI:-}" \
    BLENDER_MANIKIN_REQUIRE_BLENDER_BINARY="${BLENDER_MANIKIN_REQUIRE_BLENDER_BINARY:-}" \
    /bin/bash -c 'cd /repo && "$@"' bash "$@"
}

setup() {
  if [ ! -x "$ROOTFS/usr/bin/apt-get" ] || [ ! -f "$ROOTFS/.debootstrap-done" ]; then
    command -v debootstrap >/dev/null || { apt-get update -q && apt-get install -y -q debootstrap; }
    echo "== debootstrap trixie into $ROOTFS"
    rm -rf "$ROOTFS"
    mkdir -p "$(dirname "$ROOTFS")"
    debootstrap --variant=minbase trixie "$ROOTFS" "$MIRROR" >/dev/null
    touch "$ROOTFS/.debootstrap-done"
  fi
  mount_all
  local stamp="$ROOTFS/.manikin-stamp" want
  want="$(printf '%s\n' "$PACKAGES"; cat "$REPO/requirements-bpy52.txt" "$REPO/requirements-onnxruntime.txt" "$REPO/requirements-xror.txt")"
  if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ] && [ -x "$ROOTFS$VENV/bin/python" ]; then
    echo "Debian 13 root up to date: $ROOTFS"
  else
    echo "== apt-get install $PACKAGES"
    in_root apt-get update -q >/dev/null
    # shellcheck disable=SC2086
    in_root apt-get install -y -q --no-install-recommends $PACKAGES >/dev/null
    echo "== $VENV: requirements-bpy52.txt"
    [ -x "$ROOTFS$VENV/bin/python" ] || in_root python3 -m venv "$VENV"
    in_root "$VENV/bin/python" -m pip install -q -r requirements-bpy52.txt
    printf '%s' "$want" > "$stamp"
  fi
  in_root "$VENV/bin/python" -c "import bpy, numpy, onnxruntime, sys; print('Debian 13 root ready: Python', sys.version.split()[0], 'bpy', bpy.app.version_string, 'numpy', numpy.__version__, 'onnxruntime', onnxruntime.__version__)"
  in_root blender --version | head -1
}

case "${1:-}" in
  setup) setup ;;
  run)
    shift
    [ $# -gt 0 ] || die "usage: tools/debian13.sh run CMD [ARGS...]"
    [ -f "$ROOTFS/.manikin-stamp" ] || die "no Debian 13 root at $ROOTFS: run 'bash tools/debian13.sh setup' first"
    mount_all
    in_root "$@"
    ;;
  *) die "usage: tools/debian13.sh setup | run CMD [ARGS...]" ;;
esac
