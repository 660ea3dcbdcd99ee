#!/usr/bin/env bash
# The README's hero image: the default scene's first frame, as `lbwater render` draws it with the
# current build. Usage: bench/hero.sh [DEVICE]   (DEVICE: a --device spec; default device if absent)
set -euo pipefail
cd "$(dirname "$0")/.."
d=()
[ -n "${1:-}" ] && d=(--device "$1")
python3 -m app.cli render scenes/pool.toml -o docs/render_pool.png \
    --width 1280 --height 720 --spp 1 --bounces 5 "${d[@]}"
