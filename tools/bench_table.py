#!/usr/bin/env python3
"""Markdown rows of the "Every scene" tables of BENCHMARKS.md from `verisplat bench --json`
reports, one row per report, in the order given:

    tools/bench_table.py a.json b.json ...
"""
import json
import os
import sys


def sci(x):
    return f"{x:.3e}".replace("e+0", "e").replace("e+", "e")


def stage(run, name):
    for s in run["stages"]:
        if s["name"] == name:
            return f"{s['median']:.1f}"
    return "-"


def main():
    print("| scene | Gaussians | pairs | preprocess | order | keys | sort | ranges | blend "
          "| frame (GPU) | wall | sort keys/s | blend evals/s | peak device B/Gaussian |")
    print("|---|" + "--:|" * 13)
    for path in sys.argv[1:]:
        for run in json.load(open(path))["runs"]:
            scene = os.path.splitext(os.path.basename(run["scene"]))[0]
            cells = [
                scene,
                f"{run['gaussians']:,}",
                f"{run['pairs']:,}",
                *(stage(run, s) for s in ("preprocess", "order", "keys", "sort", "ranges", "blend")),
                f"**{run['frame_ms']['median']:.1f}**",
                f"{run['wall_ms']['median']:.1f}",
                sci(run["sort_keys_per_s"]),
                sci(run["blend_evaluations_per_s"]),
                f"{run['device_bytes_per_gaussian']:,.0f}",
            ]
            print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
