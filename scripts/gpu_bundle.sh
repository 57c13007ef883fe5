#!/usr/bin/env bash
# What scripts/gpu_check.sh needs on a bare GPU machine (Python with numpy and scipy, no
# Rust, no registry), built here: the pprender wheel (abi3, any CPython >= 3.9) and the
# pure-Python trimesh wheel in .whl/, and the Debian packages of the Vulkan loader and of
# libglvnd in .gl/ (unpacked there where the machine lacks them: NVIDIA's Vulkan driver,
# libGLX_nvidia, needs libglvnd's libGLdispatch, and without it the H200 machine of
# 2026-11-26 found no adapter). Both folders are ignored by
# git; carry them with the working tree. Needs `make setup` and the package registries.
#   scripts/gpu_bundle.sh            (then, on the GPU machine: scripts/gpu_check.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
rm -rf .whl .gl
mkdir -p .whl .gl
.venv/bin/maturin build --release --quiet -o .whl
trimesh_version=$($PY -c "import trimesh; print(trimesh.__version__)")
$PY -m pip download -q --no-deps --only-binary=:all: -d .whl "trimesh==$trimesh_version"
lists=$(mktemp -d)
mkdir -p "$lists/partial"
apt_opts=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$lists")
apt-get "${apt_opts[@]}" update -qq
(cd .gl && apt-get "${apt_opts[@]}" download -qq libvulkan1 libglvnd0 libegl1 libgl1 libglx0 libopengl0 libgles2)
rm -rf "$lists"
ls -l .whl .gl
