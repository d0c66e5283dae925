# Part 0 of tools/slurm_test.sh (sourced by it, with its cluster up): the sbatch lines of
# docs/cluster.md's example, run as a user types them. They are read from the page (the
# first ```sh block; continuation lines joined, comments dropped), so the page and the
# test cannot drift apart. They run in a folder holding examples/ (a link to the
# repository's), the inputs the lines name and a bin/ with verisplat that goes first on
# PATH; nothing is added to their options. Then the block's verisplat lines run, and what
# the jobs wrote is checked against one process.
# Uses: repo, work, bin, data, scene, cameras, jobs, fail, count, wait_all.

# The command lines of the first ```sh block of $1, one per line.
doc_commands() {
  awk '/^```sh$/ { n++; f = (n == 1); next } /^```/ { f = 0 } f' "$1" |
    awk '{ if (sub(/\\$/, "")) { buf = buf $0; next } print buf $0; buf = "" }' |
    grep -v -e '^[[:space:]]*#' -e '^[[:space:]]*$'
}

docs=$work/docs
mkdir -p "$docs/bin"
ln -s "$repo/examples" "$docs/examples"
ln -s "$bin" "$docs/bin/verisplat"
cp "$scene" "$docs/scene.ply"
# path.json: an orbit of 32 cameras at 160x90 (32, so that each of the 4 eval shards
# gets one of the 4 test cameras, every 8th).
"$bin" render "$scene" --orbit 32 --width 160 --height 90 --export-cameras "$docs/path.json" \
  --frames 0 -o "$work/docs-probe.png" -q
# model/: a "trained model" (the scene and the path's cameras); data/images: its photos,
# the finer LOD3 scene's renders; models/: two models, one sub-folder each.
model_dir() { # folder, scene
  mkdir -p "$1/point_cloud/iteration_7000"
  ln -s "$2" "$1/point_cloud/iteration_7000/point_cloud.ply"
  ln -s "$docs/path.json" "$1/cameras.json"
}
model_dir "$docs/model" "$docs/scene.ply"
model_dir "$docs/models/lod6" "$docs/scene.ply"
model_dir "$docs/models/lod3" "$data/playbot_lod3_31k_sh2.ply"
"$bin" render "$data/playbot_lod3_31k_sh2.ply" --cameras "$docs/path.json" \
  -o "$docs/data/images/{name}.png" -q

commands=$(doc_commands "$repo/docs/cluster.md")
submits=$(grep -v '^verisplat ' <<<"$commands")
[ "$(grep -c 'sbatch .*examples/slurm/' <<<"$submits")" -ge 4 ] \
  || fail "docs/cluster.md's example submits fewer than 4 scripts: $submits"
echo "slurm_test: 0. the sbatch lines of docs/cluster.md, as written:" >&2
sed 's/^/    /' <<<"$submits" >&2
if ! (cd "$docs" && PATH=$docs/bin:$PATH bash -euo pipefail -c "$submits") \
  >"$work/docs.out" 2>&1; then
  fail "docs/cluster.md's sbatch lines failed: $(cat "$work/docs.out")"
fi
while read -r id; do
  jobs+=("$id")
done < <(sed -n 's/^Submitted batch job \([0-9]*\).*/\1/p' "$work/docs.out")
wait_all
# The example's verisplat lines (the --verify after the array).
while read -r line; do
  (cd "$docs" && PATH=$docs/bin:$PATH bash -euo pipefail -c "$line") \
    || fail "docs/cluster.md: '$line' failed after the jobs; their logs: $(tail -n 5 "$docs"/*.out)"
done < <(grep '^verisplat ' <<<"$commands")
"$bin" render "$docs/scene.ply" --cameras "$docs/path.json" -o "$work/docs-one/frame_%05d.png" -q
[ "$(count "$docs"/renders/*.png)" = 32 ] || fail "the docs' render array wrote $(count "$docs"/renders/*.png) of 32 frames"
for f in "$work"/docs-one/*; do
  cmp -s "$f" "$docs/renders/$(basename "$f")" || fail "docs: $(basename "$f") differs from one process's"
done
(cd "$docs" && "$bin" eval model/ --images data/images -o eval_one -q >/dev/null)
for f in report.json report.csv; do
  cmp "$docs/eval_one/$f" "$docs/rep/$f" || fail "docs: the merged $f differs from one process's"
done
(cd "$docs" && "$bin" eval models/lod3 --images data/images -o lod3_one -q >/dev/null)
cmp "$docs/lod3_one/report.json" "$docs/eval_models/lod3/report.json" \
  || fail "docs: eval_models.sbatch's report of lod3 differs from one process's"
[ -f "$docs/eval_models/lod6/report.json" ] || fail "docs: eval_models.sbatch wrote no report of lod6"
for i in 0 1; do
  f=$docs/bench/sweep.shard-$i-of-2.json
  [ "$(grep -c '"gaussians"' "$f")" = 1 ] || fail "docs: bench_sweep.sbatch: $f does not hold one run"
done
echo "slurm_test: 0. docs/cluster.md's example ran as written: 32 frames identical to one" \
  "process, the merged eval equal to one process's, 2 models and 2 sweep shards" >&2
