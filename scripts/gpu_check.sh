#!/usr/bin/env bash
# The one-call GPU check (scripts/gpu_check.py says what it checks): on a machine with
# only Python (>= 3.9, with numpy and scipy), installs the wheels of scripts/gpu_bundle.sh
# (.whl/) into a private folder without any index, unpacks the Vulkan loader (.gl/*.deb)
# when the system has none, and runs the check. Arguments go to gpu_check.py:
#   scripts/gpu_check.sh [--device gpu|cpu|auto] [--write docs/gpu-benchmark.md] [--budget SECONDS]
# PYTHON selects the interpreter (default python3).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
ls .whl/pprender-*.whl >/dev/null 2>&1 || { echo "gpu_check: no .whl/pprender-*.whl (run scripts/gpu_bundle.sh)" >&2; exit 2; }
# the Vulkan loader, and libglvnd, which NVIDIA's Vulkan driver (libGLX_nvidia) needs
if ! ldconfig -p | grep -q 'libvulkan\.so\.1' || ! ldconfig -p | grep -q 'libGLdispatch\.so\.0'; then
  ls .gl/*.deb >/dev/null 2>&1 || { echo "gpu_check: no Vulkan loader or libglvnd and no .gl/*.deb (scripts/gpu_bundle.sh)" >&2; exit 2; }
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
fi
# NVIDIA's Vulkan driver manifest where the driver is mounted outside the system's paths
nvidia_icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [ -z "${VK_DRIVER_FILES:-}${VK_ICD_FILENAMES:-}" ] && [ -f "$nvidia_icd" ]; then
  export VK_DRIVER_FILES=$nvidia_icd
fi
site=$(mktemp -d)
"$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target "$site" .whl/*.whl
export PYTHONPATH="$site${PYTHONPATH:+:$PYTHONPATH}" NODEVICE_SELECT=1
"$PY" -c "import pprender, sys; sys.exit(0 if pprender.__file__.startswith('$site') else 'gpu_check: pprender not from the wheel: ' + pprender.__file__)"
exec "$PY" scripts/gpu_check.py "$@"
