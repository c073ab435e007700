#!/usr/bin/env bash
# The main job on the embedded defaults, from nothing:
#   set up -> simulate Scenario I (virtual scan + ground truth + model library)
#   -> sbsc detect -> sbsc evaluate (the paper's Table 1) -> review app on the result.
# Options: --no-serve  stop after the evaluation (headless check)
#          --scenario II  use the low-contrast scenario
#          --scene one_room  a bundled scene instead (one_room simulates in seconds)
#          --runs DIR  where the run folders go (default: runs/)
set -euo pipefail
cd "$(dirname "$0")/.."
serve=1; scenario=I; scene=""; runs=runs
while [ $# -gt 0 ]; do
  case "$1" in
    --no-serve) serve=0 ;;
    --scenario) scenario="$2"; shift ;;
    --scene) scene="$2"; shift ;;
    --runs) runs="$2"; shift ;;
    *) echo "demo: unknown option $1" >&2; exit 2 ;;
  esac
  shift
done
bash scripts/setup.sh
if [ -n "$scene" ]; then
  which=(--scene "$scene"); run="$runs/$scene"; name="Sample: $scene"
else
  which=(--scenario "$scenario"); run="$runs/scenario_${scenario}"; name="Sample: Scenario ${scenario}"
fi
mkdir -p "$run"  # sbsc refuses an output folder whose parent does not exist
sbsc=.venv/bin/sbsc
if [ ! -f "$run/scan/scan.ply" ]; then
  "$sbsc" simulate "${which[@]}" --out "$run/scan"
fi
"$sbsc" detect "$run/scan/scan.ply" --models "$run/scan/models" \
  --expected "$run/scan/expected.json" --out "$run/detect"
"$sbsc" evaluate --detections "$run/detect/detections.json" \
  --truth "$run/scan/ground_truth.json" --json "$run/evaluation.json"
if [ "$serve" = 1 ]; then
  .venv/bin/python -m app.sample "$run/scan/scan.ply" "$run/detect" \
    --models "$run/scan/models" --name "$name"
  echo "demo: the review app opens on the sample project; stop it with Ctrl-C"
  exec "$sbsc" serve --open
fi
