#!/bin/bash
# Table 3 in both configurations at a larger scale on a lent GPU machine (docs page "The network",
# section "Table 3 in two configurations"): 224-px scenes and crops, 12,000 training scenes, 400
# VR-balanced test scenes, 10 epochs, seeds 0-2, the shipped decoder-neutral encoder. Sized for
# one GPU's 15 minutes: the encoder stays frozen (its features are computed once per
# configuration, so the 18 runs train decoders only); FINE_TUNE=1 trains it too at 0.1x the rate
# (about 10x the time: fewer seeds or scenes then). Prepare .gl and .whl as
# tools/pretrain_on_device.sh's header says and name both in `carry`; results land in $OUT:
#   tools/table3_on_device.sh            # then commit $OUT/table3_gpu.json with the log
set -e
. "$(dirname "$0")/device_setup.sh"
OUT=${OUT:-/tmp/table3_out}
mkdir -p "$OUT"
EXTRA=""
if [ "${FINE_TUNE:-0}" = 1 ]; then EXTRA="--fine-tune"; fi
set -o pipefail
# shellcheck disable=SC2086  # EXTRA is meant to split
python3 benchmarks/dev/table3_two_configs.py --data /tmp/t3data --out /tmp/t3runs \
  --results "$OUT/table3_gpu.json" --train-scenes "${SCENES:-12000}" --test-scenes 400 \
  --image-size 224 --epochs "${EPOCHS:-10}" --seeds "${SEEDS:-0,1,2}" --device cuda \
  --workers "$(nproc)" $EXTRA 2>&1 | tee "$OUT/table3_gpu_log.txt"
