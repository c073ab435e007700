#!/usr/bin/env bash
# The main job on the embedded defaults, from nothing:
#   set up -> simulate Scenario I (virtual scan + ground truth + model library)
#   -> sbsc detect -> sbsc evaluate (the paper's Table 1)
#   -> sbsc import (the review project, its 3D scene prepared) -> sbsc serve (the review app).
# Options: --no-serve  stop after the import; a later `sbsc serve` shows the project
#          --port P  the review app's port (default 8000); a busy port is refused before any work
#          --scenario II  use the low-contrast scenario
#          --scene one_room  a bundled scene instead (one_room simulates in seconds)
#          --runs DIR  where the run folders go (default: runs/)
set -euo pipefail
cd "$(dirname "$0")/.."
serve=1; scenario=I; scene=""; runs=runs; port=8000
while [ $# -gt 0 ]; do
  case "$1" in
    --no-serve) serve=0 ;;
    --port) port="${2:-}"; shift ;;
    --scenario) scenario="$2"; shift ;;
    --scene) scene="$2"; shift ;;
    --runs) runs="$2"; shift ;;
    *) echo "demo: unknown option $1" >&2; exit 2 ;;
  esac
  shift
done
if ! [[ "$port" =~ ^[0-9]+$ ]] || [ "$port" -lt 1 ] || [ "$port" -gt 65535 ]; then
  echo "demo: --port must be a number from 1 to 65535, got '$port'" >&2; exit 2
fi
if [ "$serve" = 1 ] && (exec 3<>"/dev/tcp/127.0.0.1/$port") 2>/dev/null; then
  echo "demo: port $port is busy (another program listens on it); choose another with --port P" >&2; exit 2
fi
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
"$sbsc" import "$run/detect" --scan "$run/scan/scan.ply" --models "$run/scan/models" --name "$name"
echo
echo "demo: results in $run/"
echo "        detect/detections.json  the objects found (detect/orthoimages/: wall images)"
echo "        evaluation.json         Table 1 above, as JSON"
echo "      review project \"$name\" in the review app's data folder"
if [ "$serve" = 1 ]; then
  echo "demo: the review app opens on it at http://localhost:$port/ ; stop it with Ctrl-C"
  exec "$sbsc" serve --port "$port" --open
fi
echo "demo: next, review the objects in the browser:  $sbsc serve   (then open http://localhost:8000/)"
