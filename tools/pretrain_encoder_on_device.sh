#!/bin/bash
# Make the pretrained hand encoder on a lent GPU machine (docs page "Why the paper starts from pretrained weights", section "The pretrained hand encoder"):
# the scenes once, then up to two trainings on them (run A, run B), whose arguments are given as
# two quoted strings; each run's file and history are copied to $OUT/peA, $OUT/peB as they come.
# Prepare .gl and .whl as tools/pretrain_on_device.sh's header says and name both in `carry`.
#   HANDMESH_COMMIT=<commit> tools/pretrain_encoder_on_device.sh \
#     "--init none --max-train-seconds 140" "--init network --lr 1e-3 --max-train-seconds 140"
# The arguments both runs share (scenes, seeds, the generation's budget) come from $COMMON.
set -e
. "$(dirname "$0")/device_setup.sh"
OUT=${OUT:-/tmp/pe_out}
COMMON=${COMMON:---train-scenes 40000 --val-scenes 400 --max-generate-seconds 240}
mkdir -p "$OUT/peA" "$OUT/peB"
copy() {
  for n in peA peB; do for f in /tmp/$n/hand_encoder_pretrained.pt /tmp/$n/history.json; do
    if [ -f "$f" ]; then cp "$f" "$OUT/$n/.copy" && mv "$OUT/$n/.copy" "$OUT/$n/$(basename "$f")"; fi
  done; done
}
(while sleep 10; do copy; done) >/dev/null 2>&1 &
copier=$!
set +e -o pipefail
# shellcheck disable=SC2086  # the argument strings are meant to split
python3 -m handmesh_tutorial.apps.cli pretrain-encoder --out /tmp/peA --no-progress $COMMON $1 2>&1 \
  | tee "$OUT/logA.txt"
rc=$?
if [ -n "$2" ]; then
  # run A's scenes and crops, read in place (a link in --out would be refused)
  # shellcheck disable=SC2086
  python3 -m handmesh_tutorial.apps.cli pretrain-encoder --out /tmp/peB --scenes-from /tmp/peA \
    --no-progress $COMMON $2 2>&1 | tee "$OUT/logB.txt"
  rc=$((rc + $?))
fi
kill $copier 2>/dev/null
copy
ls -laR "$OUT"
exit $rc
