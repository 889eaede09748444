#!/bin/bash
# Run `handmesh pretrain` on a lent GPU machine whose Python has torch but not this package's
# rendering dependencies, as the shipped pretrained network was made (docs page "The pretrained
# model"). Arguments go to `handmesh pretrain`; outputs land in /tmp/pt and are copied to $OUT.
#
# Prepare once, on the machine that sends the working tree (it must reach the package
# registries), and list .gl and .whl in the device tool's `carry`:
#   echo /.gl/ >> .git/info/exclude; echo /.whl/ >> .git/info/exclude; mkdir -p .gl .whl
#   (cd .gl && apt-get download libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#     --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform any -d .whl \
#     pyrender==0.1.45 pyglet==2.1.19 trimesh==5.2.0 rtree==1.4.1 manifold3d==3.5.4 \
#     freetype-py==2.5.1
#   .venv/bin/pip wheel --no-deps -w .whl PyOpenGL==3.1.0      # sdist only: build the wheel here
# The shipped file's GPU runs (docs page "The pretrained model"), run 1 from random weights:
#   HANDMESH_COMMIT=<commit> tools/pretrain_on_device.sh --train-scenes 20000 --val-scenes 300 \
#     --epochs 16 --batch-size 128 --max-generate-seconds 150 --max-train-seconds 230
# and run 4, continuing the shipped weights on new scenes (the commit must hold the shipped file;
# a new run takes a new --data-seed: 1200 is the next unused one):
#   HANDMESH_COMMIT=<commit> tools/pretrain_on_device.sh --init pretrained --data-seed 400 \
#     --lr 3e-4 --train-scenes 40000 --val-scenes 300 --epochs 16 --batch-size 128 \
#     --max-generate-seconds 240 --max-train-seconds 240
# On a machine that stays warm between calls, /tmp/pt survives: running the same line again
# resumes (the scenes are kept, training continues from its last checkpoint).
set -e
. "$(dirname "$0")/device_setup.sh"
python3 -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"
OUT=${OUT:-/tmp/pt_out}
mkdir -p "$OUT"
files="/tmp/pt/msmr_net_pretrained.pt /tmp/pt/msmr_net_float16.pt /tmp/pt/train/metrics.csv"
# copy the exports out every 10 s, so a run killed at the command's time limit still returns them
(while sleep 10; do for f in $files; do
   if [ -f "$f" ]; then cp "$f" "$OUT/.copy" && mv "$OUT/.copy" "$OUT/$(basename "$f")"; fi
 done; done) >/dev/null 2>&1 &
copier=$!
set +e -o pipefail
python3 -m handmesh_tutorial.apps.cli pretrain --out /tmp/pt --no-progress "$@" 2>&1 | tee "$OUT/log.txt"
rc=$?
kill $copier 2>/dev/null
for f in $files; do if [ -f "$f" ]; then cp "$f" "$OUT/"; fi; done
ls -la "$OUT"
exit $rc
