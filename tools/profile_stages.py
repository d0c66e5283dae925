#!/usr/bin/env python3
"""Where llvmpipe spends a frame's CPU time, shader by shader (BENCHMARKS.md, "Profile").

Runs `verisplat bench` under `perf record` and sorts the samples into:
  - shader code: llvmpipe JIT-compiles each compute pipeline into its own block of
    anonymous executable memory, which perf reports as `[unknown]` or `/tmp/perf-PID.map`
    (this Mesa writes no perf map, so the blocks carry no names). Samples are grouped into
    blocks by address (a gap of more than --gap bytes starts a new block) and the blocks
    are listed in the order the frame first runs them, with the time window they ran in;
  - the Vulkan driver (libvulkan_lvp: command processing, descriptor set-up), libm, libc,
    the kernel (page faults, thread wake-ups) and verisplat's own host code.

Usage (release build, an otherwise idle machine):
  tools/profile_stages.py [--frames N] [--gap BYTES] [--keep perf.data] -- BENCH ARGS...
e.g.
  tools/profile_stages.py -- ../shared/data/playbot_lod2_125k_sh2.ply \\
      --cameras ../shared/data/playbot_orbit_cameras.synthetic.json

The first block seen runs first in the frame, so the block order follows the dispatch
order: preprocess, then the depth sort (setup, histogram, scan, scatter, which the pair sort
reuses), the depth-order gather, keys, ranges, blend. The bench's own per-stage GPU
timestamps are printed alongside for matching windows to stages.
"""
import argparse
import bisect
import collections
import os
import subprocess
import sys
import tempfile


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--binary", default="target/release/verisplat")
    ap.add_argument("--frames", type=int, default=5)
    ap.add_argument("--gap", type=int, default=4096, help="address gap between shader blocks")
    ap.add_argument("--keep", help="keep perf.data here")
    ap.add_argument("bench_args", nargs=argparse.REMAINDER)
    a = ap.parse_args()
    args = [x for x in a.bench_args if x != "--"]
    if not args:
        ap.error("give the bench arguments after --")
    data = a.keep or os.path.join(tempfile.mkdtemp(), "perf.data")
    cmd = ["perf", "record", "-q", "-o", data, "--", a.binary, "bench", *args,
           "--frames", str(a.frames), "--warmup", "1"]
    print("$", " ".join(cmd), file=sys.stderr)
    bench = subprocess.run(cmd, capture_output=True, text=True)
    if bench.returncode != 0:
        sys.exit(f"perf/bench failed:\n{bench.stderr}")
    stage_lines = [l for l in (bench.stdout + bench.stderr).splitlines()
                   if l.split(" ")[0] in ("stage", "preprocess", "order", "scan", "keys", "sort",
                                          "ranges", "blend", "readback", "frame", "wall")]
    script = subprocess.run(["perf", "script", "-i", data, "-F", "time,ip,dso", "-G"],
                            capture_output=True, text=True, check=True).stdout
    samples = []
    for line in script.splitlines():
        p = line.split()
        if len(p) < 3:
            continue
        try:
            samples.append((float(p[0].rstrip(":")), int(p[1], 16), " ".join(p[2:])))
        except ValueError:
            continue
    samples.sort()

    def is_jit(dso):
        return "[unknown]" in dso or ("/perf-" in dso and dso.endswith(".map)"))

    ips = sorted({ip for _, ip, dso in samples if is_jit(dso)})
    blocks = []
    for ip in ips:
        if blocks and ip - blocks[-1][1] < a.gap:
            blocks[-1][1] = ip
        else:
            blocks.append([ip, ip])
    starts = [b[0] for b in blocks]
    per_block = collections.defaultdict(list)
    other = collections.Counter()
    for t, ip, dso in samples:
        if is_jit(dso):
            per_block[bisect.bisect_right(starts, ip) - 1].append(t)
        else:
            name = os.path.basename(dso.strip("()"))
            if "lvp" in name:
                name = "Vulkan driver (libvulkan_lvp)"
            elif name.startswith("[kernel"):
                name = "kernel"
            elif name.startswith("libm"):
                name = "libm"
            elif name.startswith("libc"):
                name = "libc"
            other[name] += 1
    total = len(samples)
    jit_total = sum(len(v) for v in per_block.values())
    t0 = samples[0][0] if samples else 0.0
    print("\n".join(stage_lines))
    print(f"\nsamples: {total} (about {total / 4000:.1f} CPU s at perf's default 4000 Hz);"
          f" in shader code: {100 * jit_total / max(total, 1):.1f} %")
    print("\nshader blocks in order of first run (s from the start of the recording):")
    print(f"{'#':>3} {'first s':>8} {'last s':>8} {'samples':>8} {'% all':>6} {'% shader':>8}  address")
    order = sorted(per_block, key=lambda k: per_block[k][0])
    for rank, k in enumerate(order):
        ts = per_block[k]
        if len(ts) * 1000 < jit_total:  # under 0.1 % of shader samples
            continue
        print(f"{rank:>3} {ts[0] - t0:8.3f} {ts[-1] - t0:8.3f} {len(ts):8d} "
              f"{100 * len(ts) / total:6.1f} {100 * len(ts) / max(jit_total, 1):8.1f}  "
              f"{blocks[k][0]:#x}-{blocks[k][1]:#x}")
    print("\noutside shader code:")
    for name, n in other.most_common(8):
        print(f"  {100 * n / total:5.1f} %  {name}")


if __name__ == "__main__":
    main()
