#!/usr/bin/env bash
# Lichtblick (the open-source Foxglove Studio) as a web app, built once from its source at a
# pinned commit into ~/.cache/oricf/lichtblick/COMMIT/web, and Debian's Chromium, which the
# `-m viewer` tests drive headless (docs/live-view.md, docs/testing.md). Runs again without
# rebuilding.
#
#   scripts/lichtblick.sh                       # build it (about 7 minutes on 2 cores)
#   scripts/lichtblick.sh --serve [HOST:PORT]   # serve it (127.0.0.1:8080) with the live
#                                               # view's layout, building it first if needed
#   scripts/lichtblick.sh --where               # the built app's folder (exit 2: not built)
#
# The source comes from ORICF_LICHTBLICK_GIT: a local clone (or bare mirror) of Lichtblick's
# repository, or a URL to fetch the one commit from (default: the project on GitHub). It needs
# git, Node.js 20+ with corepack, and the npm registry (yarn and the app's packages).
set -euo pipefail
LICHTBLICK_COMMIT=66adecb99ca4363b1028c750919c9046609f5c85   # v1.28.1
LICHTBLICK_GIT="${ORICF_LICHTBLICK_GIT:-https://github.com/lichtblick-suite/lichtblick}"
CACHE="${ORICF_CACHE:-$HOME/.cache/oricf}"
DIR="$CACHE/lichtblick/$LICHTBLICK_COMMIT"
SRC="$DIR/src"
WEB="$DIR/web"
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
PYTHON="$HERE/../.venv/bin/python"
[[ -x "$PYTHON" ]] || PYTHON=python3
# Versions of the lockfile that the npm registry may lack (registry mirrors lag behind
# Lichtblick's own packages), pinned to earlier releases of the same packages; the build
# type-checks against them. The others stay as the lockfile has them.
PINS='{"@lichtblick/tsconfig": "1.0.0", "@lichtblick/eslint-plugin": "1.0.4",
       "@lichtblick/rosbag2": "1.0.0", "@lichtblick/rosbag2-web": "1.0.0",
       "flatbuffers_reflection": "0.0.7"}'
# Binary test fixtures and design files the web build never reads.
UNUSED=(e2e/fixtures/assets/demo-shuffled.bag
        packages/suite-base/src/test/fixtures/demo-shuffled.bag
        packages/suite-desktop/resources/icon/BagIcon.afdesign)

die() { echo "lichtblick.sh: $*" >&2; exit 1; }

need_tools() {
    command -v git >/dev/null || die "git is missing: apt-get install -y git"
    command -v node >/dev/null && node -e 'process.exit(parseInt(process.versions.node) < 20 ? 1 : 0)' \
        || die "Node.js 20 or later is missing (scripts/setup.sh --dev installs Node.js)"
    command -v corepack >/dev/null \
        || die "corepack is missing (it comes with Node.js; or: npm install -g corepack)"
}

chromium() {
    if command -v chromium >/dev/null || command -v chromium-browser >/dev/null; then
        return
    fi
    if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null; then
        apt-get install -y chromium >/dev/null || die "apt-get could not install chromium"
    else
        die "Chromium is missing: sudo apt-get install -y chromium"
    fi
}

fetch_source() {
    rm -rf "$SRC" && mkdir -p "$SRC"
    if [[ -d "$LICHTBLICK_GIT" ]]; then   # a local clone or mirror: the commit's files
        git -C "$LICHTBLICK_GIT" archive "$LICHTBLICK_COMMIT" -- . \
            "${UNUSED[@]/#/:(exclude)}" 2>"$DIR/archive.log" | tar -x -C "$SRC"
    else
        git -C "$SRC" init -q
        git -C "$SRC" fetch -q --depth 1 "$LICHTBLICK_GIT" "$LICHTBLICK_COMMIT"
        git -C "$SRC" checkout -q FETCH_HEAD
    fi
    [[ -f "$SRC/package.json" ]] || die "no Lichtblick source at $LICHTBLICK_COMMIT from \
$LICHTBLICK_GIT: set ORICF_LICHTBLICK_GIT to a clone of https://github.com/lichtblick-suite/lichtblick"
}

build() {
    need_tools
    mkdir -p "$DIR"
    echo "building Lichtblick $LICHTBLICK_COMMIT in $SRC (log: $DIR/build.log)"
    fetch_source
    local registry
    registry="$(npm config get registry 2>/dev/null || true)"
    registry="${registry%/}"
    # Each step ends the subshell on failure: `set -e` does not hold left of `||`.
    (
        cd "$SRC" || exit 1
        node -e 'const fs = require("fs"), p = JSON.parse(fs.readFileSync("package.json"));
                 Object.assign(p.resolutions, JSON.parse(process.argv[1]));
                 fs.writeFileSync("package.json", JSON.stringify(p, null, 2) + "\n");' "$PINS" || exit 1
        # Yarn itself (corepack) and the packages from the npm registry; no binaries from
        # elsewhere (Electron and Playwright browsers are not needed for the web app).
        export COREPACK_ENABLE_DOWNLOAD_PROMPT=0 ELECTRON_SKIP_BINARY_DOWNLOAD=1 \
            PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 HUSKY=0 YARN_ENABLE_IMMUTABLE_INSTALLS=0
        [[ -n "$registry" ]] && export COREPACK_NPM_REGISTRY="$registry" \
            YARN_NPM_REGISTRY_SERVER="$registry"
        corepack yarn install || exit 1
        # The pinned tsconfig 1.0.0 predates TypeScript 6, which the lockfile brings: its
        # moduleResolution "node" is deprecated there, an error unless acknowledged.
        node -e 'const fs = require("fs"), f = "node_modules/@lichtblick/tsconfig/base.json";
                 const s = fs.readFileSync(f, "utf8");
                 if (!s.includes("ignoreDeprecations")) fs.writeFileSync(f, s.replace(
                     /"moduleResolution": "node",/, "$&\n    \"ignoreDeprecations\": \"6.0\","));' || exit 1
        corepack yarn run web:build:prod
    ) >"$DIR/build.log" 2>&1 || die "the build failed; the end of $DIR/build.log:
$(tail -20 "$DIR/build.log")"
    rm -rf "$WEB.new" && cp -r "$SRC/web/.webpack" "$WEB.new"
    find "$WEB.new" -name '*.map' -delete   # source maps: half the size, for debugging only
    mv "$WEB.new" "$WEB"
    rm -rf "$SRC"   # its node_modules are about 2 GB; the app is in $WEB
    echo "Lichtblick built in $WEB"
}

case "${1:-}" in
    --where)
        [[ -f "$WEB/index.html" ]] || { echo "Lichtblick is not built: run $0" >&2; exit 2; }
        echo "$WEB" ;;
    --serve)
        [[ -f "$WEB/index.html" ]] || build
        exec "$PYTHON" "$HERE/lichtblick_serve.py" "$WEB" --listen "${2:-127.0.0.1:8080}" ;;
    "")
        chromium
        if [[ -f "$WEB/index.html" ]]; then echo "Lichtblick is built in $WEB"; else build; fi ;;
    *)
        sed -n '2,14p' "$0" >&2; exit 2 ;;
esac
