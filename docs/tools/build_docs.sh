#!/usr/bin/env bash
# Build the documentation site strictly, execute every code block of its pages and smoke-run the examples.
#   docs/tools/build_docs.sh [--quick] [--skip-examples] [--only=PART] [SITE_DIR]   (SITE_DIR defaults to /tmp/site)
# Steps: (1) the generated reference tables are current (docs/tools/gen_reference.py --check);
# (2) mkdocs build --strict (a broken link, anchor, nav entry or API reference fails);
# (3) pytest --markdown-docs on docs/index.md and docs/reference, then the home page's shell blocks; the guides'
#     Python and shell blocks in order with their stored outputs checked (.ci/doc_commands.py --python; tiny
#     sizes, ~6 min on 2 cores);
# (4) every examples/*.py with --quick (< ~1 min each), unless --skip-examples.
# --only=PART runs one independent part: site (1-2), home (the home page and the reference pages of 3), a guide
# (docs/guides/NAME.md: its blocks of 3) or an example (examples/NAME.py). The parts share no files, so they may run
# at the same time (.ci/smoke.py runs them two at a time); the guides' blocks stay in page order within a page.
# --quick is accepted like the scripts' --quick; the runs are always the small ones.
# mkdocstrings (griffe) reads the package from a non-editable copy: setuptools package-dir maps roadload to core/,
# roadload.envs to envs/, ..., which griffe can follow neither in the source tree nor through an editable install.
set -euo pipefail
cd "$(dirname "$0")/../.."
site=/tmp/site
examples=1
only=""
for arg in "$@"; do
  case "$arg" in
    --quick) ;;
    --skip-examples) examples=0 ;;
    --only=*) only="${arg#--only=}" ;;
    -*) echo "build_docs.sh: unknown option $arg (expected --quick, --skip-examples, --only=PART or a site directory)" >&2; exit 2 ;;
    *) site="$arg" ;;
  esac
done
case "$only" in
  ""|site|home) ;;
  docs/guides/*.md|examples/*.py) test -f "$only" || { echo "build_docs.sh: --only=$only: no such file" >&2; exit 2; } ;;
  *) echo "build_docs.sh: --only=$only (expected site, home, docs/guides/NAME.md or examples/NAME.py)" >&2; exit 2 ;;
esac
export NO_MKDOCS_2_WARNING=1 MPLBACKEND=Agg
if [ -z "$only" ] || [ "$only" = site ]; then
  python docs/tools/gen_reference.py --check
  # ROADLOAD_DOCS_PATH set by the caller: a non-editable copy of this tree is there already (.ci/docs passes the one
  # CI installed moments before); else one is made (a wheel build: ~1 min of pip mostly waiting on the index)
  pkg="${ROADLOAD_DOCS_PATH:-}"
  if [ -z "$pkg" ]; then
    pkg=$(mktemp -d /tmp/roadload_docs_pkg.XXXXXX)
    trap 'rm -rf "$pkg"' EXIT
    python -m pip install -q --no-deps --target "$pkg" . 2>&1 | { grep -v -e "^$" -e "Running pip as the 'root' user" || true; }
  fi
  test -d "$pkg/roadload/envs" || { echo "build_docs.sh: no non-editable copy of roadload in $pkg" >&2; exit 1; }
  ROADLOAD_DOCS_PATH="$pkg" python -m mkdocs build --strict -d "$site"
  echo "site written to $site"
fi
if [ -z "$only" ] || [ "$only" = home ]; then
  python -m pytest -q -p no:cacheprovider --markdown-docs docs/index.md docs/reference
  # the shell blocks of the home page, in the repo root after its Python blocks wrote the files they read
  python .ci/doc_commands.py docs/index.md --workdir .
fi
# the guides: Python and shell blocks in page order, each block's stored output checked against what it prints
if [ -z "$only" ]; then
  python .ci/doc_commands.py docs/guides/*.md --python --workdir .
elif [[ "$only" == docs/guides/*.md ]]; then
  python .ci/doc_commands.py "$only" --python --workdir .
fi
if [ -z "$only" ] && [ "$examples" = 1 ]; then
  for example in examples/*.py; do
    echo "== $example --quick"
    python "$example" --quick
  done
elif [[ "$only" == examples/*.py ]]; then
  python "$only" --quick
fi
