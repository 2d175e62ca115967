#!/usr/bin/env bash
# The project's one test command (README, .ci/run). On a fresh machine it installs what the
# reference checks need, then runs, in order:
#   1. cargo fmt --check and cargo clippy -D warnings over the workspace;
#   2. the layout invariant: the product (horizon-server) links no lab code and no baseline;
#   3. cargo test over the workspace (unit, integration and property tests), then the kill test
#      (horizon serve SIGKILLed at random under mutations; every acknowledged one survives);
#   4. the reference checks in tests/reference against third-party tools: the Khronos
#      glTF-Validator (npm gltf-validator), trimesh, and an independent glTF reading in numpy;
#   5. the web viewer in headless Chromium (tests/web: playwright-core and Debian's chromium,
#      installed here when missing) against a real horizon serve.
# The Python venv (trimesh, fast-simplification, pymeshlab, point-cloud-utils) and the npm
# validator are installed once under $HORIZON_TOOLS (default ~/.cache/horizon-tools).
set -euo pipefail
cd "$(dirname "$0")/.."
tools="${HORIZON_TOOLS:-$HOME/.cache/horizon-tools}"
mkdir -p "$tools"

# Each step also says how much disk is left: CI's disk is small, and a full one fails a build
# with an error far from its cause.
step() { printf '\n== %s (disk free: %s)\n' "$*" "$(df -h . | awk 'NR == 2 { print $4 }')"; }

step "installing reference tools into $tools (once)"
if [ ! -x "$tools/venv/bin/python" ]; then
  python3 -m venv "$tools/venv"
fi
if ! "$tools/venv/bin/python" -c 'import trimesh, fast_simplification, pymeshlab, point_cloud_utils, numpy, scipy' 2>/dev/null; then
  "$tools/venv/bin/pip" install --quiet --disable-pip-version-check \
    numpy scipy trimesh fast-simplification pymeshlab point-cloud-utils
fi
if [ ! -d "$tools/npm/node_modules/gltf-validator" ]; then
  mkdir -p "$tools/npm"
  (cd "$tools/npm" && npm init -y >/dev/null && npm install --silent --no-audit --no-fund gltf-validator@2.0.0-dev.3.10 >/dev/null)
fi
if [ ! -d "$tools/npm/node_modules/playwright-core" ]; then
  (cd "$tools/npm" && npm install --silent --no-audit --no-fund playwright-core@1 >/dev/null)
fi
# The browser tests drive Debian's Chromium.
chromium="${CHROMIUM:-/usr/bin/chromium}"
if [ ! -x "$chromium" ]; then
  sudo_=""
  [ "$(id -u)" -ne 0 ] && sudo_="sudo"
  $sudo_ apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_ apt-get install -y -qq chromium >/dev/null
fi

step "format and lints"
cargo fmt --all --check
cargo clippy --workspace --all-targets --quiet -- -D warnings

step "the product links no lab code and no baseline"
if cargo tree -p horizon-server -e normal --prefix none | grep -q '^horizon-lab '; then
  echo "horizon-server depends on horizon-lab" >&2
  exit 1
fi
if cargo tree -p horizon-server -e features --prefix none | grep -q 'feature "baseline"'; then
  echo "horizon-server enables a baseline feature" >&2
  exit 1
fi

step "cargo test"
cargo test --workspace --quiet

step "horizon serve killed with SIGKILL under mutations, 20 times (ignored by cargo test)"
# Selected with the whole workspace so that features unify as in the run above and nothing is
# rebuilt: `-p horizon-server` alone would build every crate a second time, and CI's disk is
# small.
cargo test --workspace --quiet --test kill -- --ignored

step "reference checks (Khronos glTF-Validator, trimesh)"
# The product under test is the release horizon, built alone so that it is exactly what ships
# (built together with the lab, cargo would unify the lab's baseline features into it). The lab
# commands the checks use (gen model, gen world, distance on small models) take the debug
# horizon-lab that cargo test built.
cargo build --release --quiet -p horizon-server
export HORIZON_LAB=target/debug/horizon-lab
GLTF_VALIDATOR_DIR="$tools/npm" "$tools/venv/bin/python" tests/reference/check_models.py \
  target/release/horizon tests/reference/validate.mjs
GLTF_VALIDATOR_DIR="$tools/npm" "$tools/venv/bin/python" tests/reference/check_simplify.py \
  target/release/horizon tests/reference/validate.mjs
GLTF_VALIDATOR_DIR="$tools/npm" "$tools/venv/bin/python" tests/reference/check_aggregates.py \
  target/release/horizon tests/reference/validate.mjs

step "the web viewer in headless Chromium (tests/web)"
HORIZON=target/release/horizon PLAYWRIGHT_CORE="$tools/npm/node_modules/playwright-core" \
  CHROMIUM="$chromium" node --test tests/web/
