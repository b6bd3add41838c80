#!/usr/bin/env bash
# Peak memory of reading long raw captures and bags: the sample VLP-16 capture's first whole
# turn repeated into captures of several lengths (bench/long_capture.py), each read by `lex3d
# info` and coded by `lex3d compress` (one model file a turn, 2 cm, two threads), and its
# turns written as a ROS bag of PointCloud2 (`lex3d convert`, where lex3d reads bags) coded
# the same way. A reader that holds a scan or two at a time keeps the same peak whatever
# the length.
#
# usage: bench/capture_memory.sh [LEX3D] [TURNS...]   (default: build/lex3d, 60 600)
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
lex3d="${1:-$here/../build/lex3d}"
shift || true
turns=("${@:-60 600}")
read -r -a turns <<< "${turns[*]}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
printf "%8s %10s %12s %12s %14s %12s %12s %12s\n" turns "MB file" "info MB" "info s" "compress MB" "compress s" "bag MB" "bag s"
for n in "${turns[@]}"; do
  cap="$work/vlp16_$n.pcap"
  python3 "$here/long_capture.py" "$here/../samples/vlp16_velodyne_example.pcap" "$cap" "$n" > /dev/null
  mb=$(( $(stat -c %s "$cap") / 1000000 ))
  /usr/bin/time -f "%M %e" -o "$work/t_info" "$lex3d" info "$cap" --json > /dev/null
  mkdir -p "$work/out_$n"
  /usr/bin/time -f "%M %e" -o "$work/t_comp" "$lex3d" compress "$cap" -o "$work/out_$n/t.lex3dm" --max-error 0.02 > /dev/null
  read -r info_kb info_s < "$work/t_info"
  read -r comp_kb comp_s < "$work/t_comp"
  bag_mb="-" bag_s="-"
  if "$lex3d" convert "$cap" "$work/vlp16_$n.bag" > /dev/null 2>&1; then
    rm -rf "$work/out_$n" && mkdir -p "$work/out_$n"
    /usr/bin/time -f "%M %e" -o "$work/t_bag" "$lex3d" compress "$work/vlp16_$n.bag" -o "$work/out_$n/t.lex3dm" --max-error 0.02 > /dev/null
    read -r bag_kb bag_s < "$work/t_bag"
    bag_mb=$((bag_kb / 1024))
  fi
  printf "%8s %10s %12s %12s %14s %12s %12s %12s\n" "$n" "$mb" "$((info_kb / 1024))" "$info_s" "$((comp_kb / 1024))" "$comp_s" "$bag_mb" "$bag_s"
  rm -rf "$work/out_$n" "$cap" "$work/vlp16_$n.bag"
done
