#!/usr/bin/env bash
# Build the documentation site strictly and execute every code block of the guides.
#   scripts/build_docs.sh [--quick] [SITE_DIR]      (SITE_DIR defaults to /tmp/site)
# --quick is accepted for the scripts/ convention; the run is always the small one (< ~2 min on 2 cores).
# mkdocstrings (griffe) reads the package from a non-editable copy: setuptools package-dir maps roadload to core/,
# roadload.envs to envs/, ..., which griffe cannot follow in the source tree or through an editable install.
set -euo pipefail
cd "$(dirname "$0")/.."
site=/tmp/site
for arg in "$@"; do
  case "$arg" in
    --quick) ;;
    -*) echo "build_docs.sh: unknown option $arg (expected --quick or a site directory)" >&2; exit 2 ;;
    *) site="$arg" ;;
  esac
done
pkg=$(mktemp -d /tmp/roadload_docs_pkg.XXXXXX)

trap 'rm -rf "$pkg"' EXIT
python -m pip install -q --no-deps --target "$pkg" . 2>&1 | grep -v "^$" || true
test -d "$pkg/roadload" || { echo "build_docs.sh: pip could not install roadload into $pkg" >&2; exit 1; }
ROADLOAD_DOCS_PATH="$pkg" python -m mkdocs build --strict -d "$site"
echo "site written to $site"
# every code block in the guides runs (pytest-markdown-docs); tiny sizes, < ~90 s
python -m pytest -q -p no:cacheprovider --markdown-docs docs/guides
