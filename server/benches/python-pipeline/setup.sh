#!/usr/bin/env bash
# Makes the Python side of the side-by-side (run.sh): the venv .venvs/pipeline with
# requirements.txt, and Polylidar3D 1.0.9 built from its PyPI source into it, as its wheels are
# built (its robust-predicate option needs sources the package leaves out). Prints the venv's
# python on stdout; progress goes to stderr. Idempotent: the build runs while `import polylidar`
# fails.
#
# Polylidar3D has wheels only for Pythons older than this machine's, and its source clones four
# repositories at configure time; thirdparty.cmake replaces that step (see there). Needs a C++
# compiler and Eigen's headers (Debian's libeigen3-dev, installed here when run as root).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../../.." && pwd)
py=$(bash "$root/scripts/python-env.sh" pipeline "$here/requirements.txt")
if "$py" -c "import polylidar" 2> /dev/null; then
  echo "$py"
  exit 0
fi
if [ ! -d /usr/include/eigen3 ]; then
  if [ "$(id -u)" = 0 ]; then
    apt-get install -y -q libeigen3-dev >&2
  else
    echo "setup: Eigen's headers are missing: sudo apt-get install libeigen3-dev" >&2
    exit 1
  fi
fi
build="$root/.venvs/pipeline-build"
sdist_sha256=e66538ba5a59d29c1cb0dab56759b72d25886a10ad38496a4960af5b13a4abeb
rm -rf "$build"
mkdir -p "$build"
"$py" -m pip download -q --no-deps --no-binary polylidar polylidar==1.0.9 -d "$build" >&2
echo "$sdist_sha256  $build/polylidar-1.0.9.tar.gz" | sha256sum -c --quiet >&2
tar xzf "$build"/polylidar-1.0.9.tar.gz -C "$build"
src="$build/polylidar-1.0.9"
cp "$here/thirdparty.cmake" "$src/thirdparty/CMakeLists.txt"
bin=$(dirname "$py")
PATH="$bin:$PATH" cmake -S "$src" -B "$build/out" -DCMAKE_BUILD_TYPE=Release \
  -DPYTHON_EXECUTABLE="$py" -DPL_BUILD_TESTS=OFF -DPL_BUILD_EXAMPLES=OFF \
  -DPL_BUILD_BENCHMARKS=OFF -DSTAND_INS="$here/stand-ins" \
  -DCMAKE_FIND_PACKAGE_TARGETS_GLOBAL=ON -Dpybind11_DIR="$("$py" -m pybind11 --cmakedir)" >&2
PATH="$bin:$PATH" cmake --build "$build/out" --target polylidar_pybind -j "$(nproc)" >&2
site=$("$py" -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")
rm -rf "$site/polylidar"
cp -r "$src/src/Python/polylidar" "$site/"
cp "$build"/out/lib/Python/polylidar_pybind*.so "$site/polylidar/"
"$py" -c "import polylidar" >&2
rm -rf "$build"
echo "$py"
