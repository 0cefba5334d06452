#!/usr/bin/env bash
# `cmake --install` and what it is for (cmake/HybgenInstall.cmake, docs/install.md):
#  1. the installed hybgen builds and runs a model from a directory outside the source tree,
#     compiling the runner against the installed runtime, not the source tree's;
#  2. docs/examples/find_package builds with find_package(hybgen) against the installed tree
#     and the kernels the installed hybgen generates, and its solve matches a closed form.
# usage: test_install.sh SOURCE_DIR BUILD_DIR WORK_DIR
set -euo pipefail
src=$1 build=$2 work=$3
rm -rf "$work"
mkdir -p "$work"
cmake --install "$build" --prefix "$work/prefix" >/dev/null
cd "$work"
cp "$src/docs/examples/find_package/decay.model" .
export HYBGEN_CACHE="$work/cache"

prefix/bin/hybgen build -v decay.model >build.log 2>&1 || { cat build.log; exit 1; }
if ! grep -q -- "-I'$work/prefix/include'" build.log; then
  echo "the runner was not compiled against the installed headers:"; cat build.log; exit 1
fi
if grep -q -- "$src/runtime" build.log; then
  echo "the runner used the source tree's runtime:"; cat build.log; exit 1
fi
prefix/bin/hybgen run decay.model --out out -q
for f in run.nc summary.json; do
  [[ -f out/$f ]] || { echo "missing out/$f"; ls out; exit 1; }
done

prefix/bin/hybgen generate decay.model -o gen >/dev/null
cmake -S "$src/docs/examples/find_package" -B example -DCMAKE_PREFIX_PATH="$work/prefix" \
  -DDECAY_KERNELS="$work/gen" >example.log 2>&1 || { cat example.log; exit 1; }
cmake --build example >>example.log 2>&1 || { cat example.log; exit 1; }
./example/decay_example
echo "install: ok"
