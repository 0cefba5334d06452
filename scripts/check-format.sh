#!/usr/bin/env bash
# The tree is clang-formatted (.clang-format): every tracked C++ source and header,
# except generated/ (hybgen's own output, checked byte for byte by the golden test).
# Exit 1 with the files and lines to fix; `clang-format -i FILE` fixes them.
set -euo pipefail
cd "$(dirname "$0")/.."
CLANG_FORMAT=${CLANG_FORMAT:-clang-format}
mapfile -t files < <(git ls-files '*.cpp' '*.hpp' '*.h' | grep -v '^generated/')
if "$CLANG_FORMAT" --dry-run --Werror "${files[@]}"; then
  echo "check-format: ${#files[@]} files are clang-formatted" >&2
else
  echo "check-format: run clang-format -i on the files above" >&2
  exit 1
fi
