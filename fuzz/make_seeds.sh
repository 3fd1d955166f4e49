#!/bin/sh
# Regenerates the seed corpora in fuzz/corpus/ from rcm's own outputs: a quick
# simulated session, a linear free-space model and a tissue law fitted on it,
# the simulator's configuration, the shipped robots, and the binary recordings
# that fuzz_make_seeds writes from the session's first samples. Every seed is
# cut to a few rows so that it stays a few KB.
#   fuzz/make_seeds.sh BUILD     (a normal build: BUILD/bin/rcm and BUILD/bin/fuzz_make_seeds)
set -eu
BUILD=$1
HERE=$(cd "$(dirname "$0")" && pwd)
RCM=$BUILD/bin/rcm
OUT=$HERE/corpus
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

"$RCM" simulate --quick --seed 1 --out "$TMP/session" >/dev/null
"$RCM" dynamics fit --model linear --out "$TMP/linear.json" "$TMP/session/free_space.csv" >/dev/null
"$RCM" tissue fit --session "$TMP/session/session.json" --model "$TMP/linear.json" --out "$TMP/tissue.json" >/dev/null

for d in csv_recording csv_rostopic session torque_model tissue_law robot sim_config; do
  mkdir -p "$OUT/$d"
done
# Recordings: the first rows of free space (no force) and of a trial (with force).
trial=$(ls "$TMP"/session/*.csv | grep -v -e free_space -e calibration -e _truth -e static | head -n 1)
head -n 7 "$TMP/session/free_space.csv" > "$OUT/csv_recording/free_space.csv"
head -n 7 "$trial" > "$OUT/csv_recording/trial_with_force.csv"
head -n 7 "$trial" > "$TMP/short.csv"
/usr/bin/python3 "$HERE/rostopic_seed.py" "$TMP/short.csv" "$OUT/csv_rostopic"
# The manifest, its recordings renamed to the files the session target provides.
/usr/bin/python3 - "$TMP/session/session.json" "$OUT/session/session.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
s["free_space"] = ["free_space.csv"]
if s.get("baseline"):
    s["baseline"] = "free_space.csv"
if s.get("calibration"):
    s["calibration"]["recording"] = "calibration.csv"
trials = s.get("trials", [])[:3]
for i, t in enumerate(trials, 1):
    t["recording"] = f"trial_{i}.csv"
    if t.get("static"):
        t["static"] = f"static_{i}.csv"
s["trials"] = trials
s["topics"] = {"joints": "/PSM1/measured_js", "force": "/PSM1/body/measured_cf"}
json.dump(s, open(sys.argv[2], "w"), indent=1)
PY
cp "$TMP/linear.json" "$OUT/torque_model/linear.json"
cp "$TMP/tissue.json" "$OUT/tissue_law/tissue_law.json"
cp "$HERE"/../data/robots/*.json "$OUT/robot/"
"$RCM" simulate --print-config > "$OUT/sim_config/default.json"
"$RCM" simulate --tissue stiffening --friction smooth --print-config > "$OUT/sim_config/stiffening_smooth.json"
echo '{"tissue": {"preset": "sliding"}, "friction": {"preset": "smooth"}}' > "$OUT/sim_config/presets.json"
"$BUILD/bin/fuzz_make_seeds" "$TMP/short.csv" "$TMP/linear.json" "$OUT" "$HERE/data/bag"
# A bag's empty topic folder is not a corpus (built without ROS).
rmdir "$OUT/ros_bag" 2>/dev/null || true
du -sh "$OUT"/* "$HERE/data/bag"
