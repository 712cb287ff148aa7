#!/usr/bin/env bash
# make demo: runs the shipped example through the CLI. Filled in as the pipeline grows.
set -euo pipefail
BIN=$1; OUT=$2
echo "demo: $BIN -> $OUT (pipeline not assembled yet)"
