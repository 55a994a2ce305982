#!/usr/bin/env bash
# Make the example recordings again (seconds, not real time: the simulated rig runs in process).
set -euo pipefail
cd "$(dirname "$0")"
for name in linear localized-1 localized-2 impacting-both; do
  python -m daq record --port "rig://?config=$name.yaml" --config "$name.yaml" --duration 10 -o "$name.mcap" --no-identify --quiet --force
done
python -m daq record --port "rig://?config=transitions.yaml" --config transitions.yaml --duration 26 -o transitions.mcap --no-identify --quiet --force
