#!/usr/bin/env bash
# Set up everything (see setup.sh) and run the whole test suite, linter included.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh --browser
exec .venv/bin/python -m pytest "$@"
