#!/usr/bin/env bash
# Downloads into .whl/ the wheels the GPU machine's image lacks (MuJoCo, MJX, Playground, Brax, rejax,
# gymnax, distrax and their missing dependencies; ~50 MiB), for Python 3.12 on x86-64 Linux.
# benchmarks/device_run.sh installs whatever .whl/ holds; carry .whl with the call.
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p .whl
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_24_x86_64 \
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --platform manylinux1_x86_64 -d .whl \
  mujoco==4.0.0 mujoco-core==4.0.0 mujoco-studio==4.0.0 glfw==2.11.0 pyopengl==3.1.10 websockets==17.4 \
  mujoco-mjx==3.17.0 trimesh==5.2.0 playground==0.2.0 brax==0.14.2 jaxopt==0.8.5 ml-collections==1.1.0 \
  rejax==0.1.3 gymnax==1.0.1 gymnasium==1.3.0 farama-notifications==0.0.6 distrax==0.1.9 \
  tfp-nightly==0.26.0.dev20261027 decorator==5.3.1 gast==0.7.0 dm-tree==0.1.10
du -sh .whl
