#!/usr/bin/env bash
# Runs every libFuzzer target of a Clang build for a bounded time, two at a time, each on a
# fresh copy of its seed corpus (tests/fuzz/corpus for the model and alphabet decoders,
# tests/fuzz/readers/<format> for the readers (bag: ROS bags, make_bag_corpus.cpp), tests/fuzz/readers/placedb for the place
# database, tests/fuzz/readers/placequery for a prepared query), with a fixed seed (-seed=1).
# Exits non-zero when any target finds a crash, a sanitizer report or a violated property; the
# input that did it is kept in the target's artifact directory.
#
#   tests/fuzz/run_fuzzers.sh BUILD_DIR [SECONDS_EACH=60] [TARGET...]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
build="${1:?usage: run_fuzzers.sh BUILD_DIR [SECONDS_EACH] [TARGET...]}"
seconds="${2:-60}"
shift $(( $# >= 2 ? 2 : 1 ))
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=(fuzz_model fuzz_alphabet fuzz_place_db fuzz_place_query)
  for d in "$here"/readers/*/; do
    name="$(basename "$d")"
    case "$name" in placedb|placequery) ;; *) targets+=("fuzz_reader_$name") ;; esac
  done
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

run_one() {
  local target="$1" seeds
  case "$target" in
    fuzz_model|fuzz_alphabet) seeds="$here/corpus" ;;
    fuzz_place_db) seeds="$here/readers/placedb" ;;
    fuzz_place_query) seeds="$here/readers/placequery" ;;
    fuzz_reader_*) seeds="$here/readers/${target#fuzz_reader_}" ;;
    *) echo "run_fuzzers: unknown target $target" >&2; return 1 ;;
  esac
  mkdir -p "$work/$target/corpus" "$work/$target/artifacts"
  cp "$seeds"/* "$work/$target/corpus/"
  local log="$work/$target/log"
  if "$build/tests/fuzz/$target" -seed=1 -max_total_time="$seconds" -print_final_stats=1 \
       -artifact_prefix="$work/$target/artifacts/" "$work/$target/corpus" > "$log" 2>&1; then
    printf '%-22s %s runs, %s exec/s, corpus %s -> %s files\n' "$target" \
      "$(grep -o 'number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$')" \
      "$(grep -o 'average_exec_per_sec: *[0-9]*' "$log" | grep -o '[0-9]*$')" \
      "$(ls "$seeds" | wc -l)" "$(ls "$work/$target/corpus" | wc -l)"
  else
    echo "$target FAILED:"; tail -n 40 "$log"
    mkdir -p fuzz-artifacts && cp "$work/$target/artifacts/"* fuzz-artifacts/ 2>/dev/null || true
    echo "(the failing input is in fuzz-artifacts/)"
    return 1
  fi
}
export -f run_one
export here build seconds work
printf '%s\n' "${targets[@]}" | xargs -P 2 -I{} bash -c 'run_one "$1"' _ {}
