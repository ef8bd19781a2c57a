#!/usr/bin/env bash
# Builds the 3D replay viewer of summary.html (viewer/viewer.js with three.js 0.187.0 from
# npm, bundled by esbuild into one classic script) under ~/.cache/workcell/viewer, the first
# time, and prints its path. Beside it, the Khronos glTF validator for
# scripts/check-summary-html.py. `workcell evaluate --gltf N` copies it beside the report when
# WORKCELL_VIEWER_JS names it or it is at that default place.
# Use: export WORKCELL_VIEWER_JS="$(scripts/fetch-viewer.sh)"
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
CACHE="${WORKCELL_VIEWER_CACHE:-$HOME/.cache/workcell/viewer}"
THREE=0.187.0
ESBUILD=0.28.2
VALIDATOR=2.0.0-dev.3.10
OUT="$CACHE/workcell-viewer.js"
STAMP="$CACHE/stamp"
WANT="three@$THREE esbuild@$ESBUILD gltf-validator@$VALIDATOR $(sha256sum "$ROOT/viewer/viewer.js" | cut -c1-16)"
if [ ! -f "$OUT" ] || [ "$(cat "$STAMP" 2>/dev/null)" != "$WANT" ]; then
    mkdir -p "$CACHE"
    (cd "$CACHE" && { [ -f package.json ] || npm init -y >/dev/null 2>&1; } \
        && npm install --silent --no-audit --no-fund \
            "three@$THREE" "esbuild@$ESBUILD" "gltf-validator@$VALIDATOR" >&2)
    cat > "$CACHE/validate-gltf.js" <<'JS'
// Prints the Khronos glTF validator's counts for one file as JSON; exit status 1 on errors.
const validator = require('gltf-validator');
const bytes = new Uint8Array(require('fs').readFileSync(process.argv[2]));
validator.validateBytes(bytes).then((r) => {
  const i = r.issues;
  console.log(JSON.stringify({errors: i.numErrors, warnings: i.numWarnings,
    messages: i.messages.slice(0, 10).map((m) => `${m.code} ${m.pointer}: ${m.message}`)}));
  process.exit(i.numErrors ? 1 : 0);
}).catch((e) => { console.error(String(e)); process.exit(2); });
JS
    cp "$ROOT/viewer/viewer.js" "$CACHE/entry.js"
    (cd "$CACHE" && node_modules/.bin/esbuild entry.js --bundle --minify --format=iife \
        --target=es2020 --legal-comments=eof --outfile="$OUT.partial" --log-level=warning >&2)
    mv "$OUT.partial" "$OUT"
    echo "$WANT" > "$STAMP"
fi
echo "$OUT"
