#!/usr/bin/env bash
# The two set-up commands of README.md, for a fresh Debian 12 machine (as root, or with sudo):
#   ./setup.sh run    install what is missing, build, run the main comparison job
#   ./setup.sh test   install what is missing, build (float, double, sanitizers), run ctest
set -euo pipefail
cd "$(dirname "$0")"

# What the main job needs (`run`), and what only the tests, benchmarks and style check need.
run_packages=(cmake make g++ pkg-config ccache libbullet-dev libeigen3-dev libassimp-dev
  nlohmann-json3-dev libcli11-dev libnanoflann-dev libqhull-dev gnuplot-nox zlib1g-dev
  # `fibremss view`: window, OpenGL (Mesa's drivers, llvmpipe where there is no GPU), panel, PNG
  libglfw3-dev libgl-dev libgl1-mesa-dri libimgui-dev libstb-dev
  # the CalculiX reference: tetgen meshes, ccx solves (run as processes)
  calculix-ccx tetgen
  # the Python module (`import fibremss`) and the README's Python example's plot
  python3-dev pybind11-dev python3-numpy python3-matplotlib)
# (xvfb, xauth: a virtual X server for the viewer's screenshot tests. python3-paraview: the
# frames read back by VTK 9 and ParaView 5.11 in Debian's /usr/bin/python3; it brings its own
# VTK and replaces python3-vtk9.)
test_packages=(valgrind libgtest-dev libgmock-dev libbenchmark-dev clang-format xvfb xauth
  python3-paraview)

# Each stage prints one line; its output goes to a log under build/setup-logs/, shown in full
# only when the stage fails.
logs=build/setup-logs
stage() {  # stage NAME COMMAND...
  local name=$1 log="$logs/$1.log"
  shift
  mkdir -p "$logs"
  printf 'setup: %-24s' "$name"
  if "$@" >"$log" 2>&1; then
    echo "ok (log: $log)"
  else
    echo "FAILED; its log, $log:"
    cat "$log"
    exit 1
  fi
}

install_missing() {  # install_missing PACKAGE...
  local missing=()
  for p in "$@"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "installing ${missing[*]}"
  local sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

jobs=$(nproc)

build() {  # build DIR [cmake options...]
  local dir=$1
  shift
  cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Release "$@"
  cmake --build "$dir" -j"$jobs"
}

case "${1:-}" in
  run)
    stage packages install_missing "${run_packages[@]}"
    # Only the fibremss tool, the Python module and their libraries: no tests, no benchmarks.
    stage configure cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DFIBREMSS_BUILD_TESTS=OFF
    stage build cmake --build build -j"$jobs" --target fibremss_cli fibremss_python
    # thigh13's CalculiX reference takes hours of CPU (comparisons/README.md, "The main job"):
    # the job takes it from scenes/references (shipped) or the cache, never solves it here.
    echo "setup: main job: fibremss compare thigh13 --set resolution=20"
    build/bin/fibremss compare thigh13 --set resolution=20 --reference-cached-only --out results/thigh13
    echo "setup: report in results/thigh13/report.md (plot: results/thigh13/speed_vs_error.png)"
    ;;
  test)
    stage packages install_missing "${run_packages[@]}" "${test_packages[@]}"
    build build -DFIBREMSS_WERROR=ON -DFIBREMSS_BUILD_TESTS=ON
    ctest --test-dir build -j"$jobs" --output-on-failure --timeout 900
    # The same suite against Bullet's double-precision variant, without the checks of the sources
    # alone (their format, links, includes and function lengths: the float run's).
    build build-double -DFIBREMSS_WERROR=ON -DFIBREMSS_DOUBLE=ON
    ctest --test-dir build-double -j"$jobs" --output-on-failure --timeout 900 -E '^(Style|Docs)\.'
    # And under AddressSanitizer + UndefinedBehaviorSanitizer, with line tables only (-g1: its
    # reports name file and line; full debug information took 1.3-1.4x as long per file). The
    # install test is left out there: its consumer is not instrumented but would link the
    # instrumented library; the checks of the sources alone as well.
    build build-asan -DFIBREMSS_WERROR=ON -DFIBREMSS_SANITIZE=address,undefined \
      -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1"
    ctest --test-dir build-asan -j"$jobs" --output-on-failure --timeout 900 -E '^(Install|Style|Docs)\.'
    ;;
  *)
    echo "usage: $0 run|test" >&2
    exit 2
    ;;
esac
