# Sourced by the per-sequence benchmarks (codec.sh, compress_stages.sh) after `cd` to the
# repository: reads [BUILD_DIR] [DATA_DIR] [SEQUENCE...] from the arguments and sets
# BUILD_DIR (default build), DATA (../shared/data), SEQS (kitti00 balm), LEX3D and WORK, a
# temporary directory removed on exit.
BUILD_DIR="${1:-build}"
DATA="${2:-../shared/data}"
shift $(( $# > 2 ? 2 : $# )) || true
SEQS=("$@")
[ ${#SEQS[@]} -gt 0 ] || SEQS=(kitti00 balm)
LEX3D="$BUILD_DIR/lex3d"
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
