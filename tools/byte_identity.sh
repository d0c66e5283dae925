#!/usr/bin/env bash
# Runs the same commands with two verisplat binaries and compares every file they write,
# byte for byte: for a change that must not change behaviour (a refactor), run it with the
# binary built before the change and the one built after.
#
#     tools/byte_identity.sh OLD_BIN NEW_BIN [WORKDIR]
#
# The commands: the renders of a shared scene in each mode and format (PNG, EXR with depth,
# alpha, depth, rgba, the compact upload), the demo scene with
# the power kernel, gsplat's rules and antialiasing, the CPU reference, a COLMAP data set
# exported from a scene, a 200-iteration training run on it (densification included), and a
# field fit and its render. Exit status 1 if any file differs or one side failed; the table names each.
set -euo pipefail
# Absolute, since each command runs in its own directory.
old=$(realpath "${1:?old binary}")
new=$(realpath "${2:?new binary}")
work=${3:-$(mktemp -d)}
data="$(cd "$(dirname "$0")/.." && pwd)/../shared/data"
mkdir -p "$work"
status=0

run() { # run NAME ARGS...: both binaries, in $work/{old,new}/NAME
  local name=$1
  shift
  for side in old new; do
    local bin=$old
    [ $side = new ] && bin=$new
    local dir="$work/$side/$name"
    rm -rf "$dir" && mkdir -p "$dir"
    (cd "$dir" && "$bin" "$@" >stdout.txt 2>stderr.txt) || {
      echo "FAILED ($side): $name: $*"
      tail -3 "$dir/stderr.txt"
      status=1
    }
  done
}

scene="$data/playbot_lod3_31k_sh2.ply"
run png render "$scene" --orbit 3 --width 160 --height 120 -o f_%02d.png
run exr render "$scene" --orbit 2 --width 160 --height 120 -o f_%02d.exr
run alpha render "$scene" --orbit 2 --width 160 --height 120 --mode alpha -o f_%02d.png
run depth render "$scene" --orbit 2 --width 160 --height 120 --mode depth -o f_%02d.png
run rgba render "$scene" --orbit 2 --width 160 --height 120 --mode rgba -o f_%02d.png
run compact render "$scene" --orbit 2 --width 160 --height 120 --compact -o f_%02d.png
run power render --demo --kernel power -o demo.png
run gsplat render "$scene" --orbit 2 --width 160 --height 120 --rules gsplat --antialiased -o f_%02d.exr
run cpu render "$scene" --orbit 1 --width 96 --height 72 --cpu -o f_%02d.exr
run dataset render "$data/playbot_lod6_1873_sh2.ply" --orbit 16 --width 96 --height 72 \
  --export-colmap data
for side in old new; do
  bin=$old
  [ $side = new ] && bin=$new
  (cd "$work/$side/dataset" && "$bin" train data -o model --iterations 200 --eval \
    --densify-from-iter 50 --densification-interval 50 --test-iterations 200 \
    --save-iterations 200 >train.txt 2>&1) || { echo "FAILED ($side): train"; status=1; }
done
run gen gen 5000 --seed 3 -o g.ply
for side in old new; do
  bin=$old
  [ $side = new ] && bin=$new
  dir="$work/$side/fit"
  rm -rf "$dir" && mkdir -p "$dir"
  (cd "$dir" && "$bin" gen --rf dipole dipole.npy --size 16 >/dev/null &&
    "$bin" fit dipole.npy -o fit.ply --steps 300 >/dev/null &&
    "$bin" render fit.ply --mode field-slice --slice-plane 0,0,0,0,0,1 --width 96 --height 72 \
      -o slice.exr >/dev/null 2>&1) || { echo "FAILED ($side): fit"; status=1; }
done

printf '%-48s %s\n' "file" "old = new"
cd "$work/old"
while IFS= read -r f; do
  case $f in */stdout.txt | */stderr.txt | */train.txt | *cfg_args) continue ;; esac
  if [ ! -f "$work/new/$f" ]; then
    printf '%-48s %s\n' "$f" "MISSING in new"
    status=1
  elif cmp -s "$f" "$work/new/$f"; then
    printf '%-48s %s\n' "$f" "identical"
  else
    printf '%-48s %s\n' "$f" "DIFFERS"
    status=1
  fi
done < <(find . -type f | sort)
exit $status
