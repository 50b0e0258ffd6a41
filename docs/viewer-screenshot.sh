#!/usr/bin/env bash
# A real screenshot of the rerun viewer on a machine without display or GPU (how the README's
# image was made): Xvfb plus Mesa's software Vulkan (lavapipe; its OpenGL driver lacks a texture
# format the viewer needs), then the viewer's own --screenshot-to, which saves at twice the window
# size and quits.
#   docs/viewer-screenshot.sh OUT.png FILE.rrd [FILE.rrd ...]
set -euo pipefail
out=$1; shift
if ! command -v xvfb-run >/dev/null || [ ! -e /usr/share/vulkan/icd.d/lvp_icd.x86_64.json ]; then
  apt-get update -qq && apt-get install -y -qq xvfb mesa-vulkan-drivers libvulkan1 >/dev/null
fi
RERUN_ANALYTICS=0 WGPU_BACKEND=vulkan xvfb-run -a -s "-screen 0 1600x900x24" \
  "$(dirname "$0")/../.venv/bin/rerun" --window-size 1600x900 --screenshot-to "$out" "$@"
