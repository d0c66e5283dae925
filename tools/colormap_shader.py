#!/usr/bin/env python3
"""Writes a neural shader (safetensors, the format `verisplat render --shader` reads) that
maps one feature channel through a colour map: an exact piecewise-linear MLP, no
training needed, so the gen -> fit -> render -> shade walkthrough works without PyTorch.

    tools/colormap_shader.py --channels K [--channel C] [--range LO,HI] -o shader.safetensors

Layer 1 (relu): hidden unit j = relu(f_C - t_j) at the colour map's knots t_j; layer 2
(none): colour = c_0 + sum_j s_j * hidden_j, the slopes s_j making the map's colours at
the knots. Values below LO get the first colour, above HI the last one's slope continues
(clamped by the writer to [0, 1]). Needs only the Python standard library.
"""

import argparse
import json
import struct
import sys

# A turbo-like map: (position in [0, 1], R, G, B).
KNOTS = [
    (0.00, 0.19, 0.07, 0.23),
    (0.15, 0.27, 0.42, 0.91),
    (0.30, 0.11, 0.80, 0.89),
    (0.45, 0.33, 0.99, 0.47),
    (0.60, 0.79, 0.94, 0.20),
    (0.75, 0.99, 0.64, 0.16),
    (0.90, 0.86, 0.25, 0.04),
    (1.00, 0.48, 0.02, 0.01),
]


def safetensors_bytes(tensors, metadata):
    header, data = {}, b""
    for name, shape, values in tensors:
        start = len(data)
        data += struct.pack(f"<{len(values)}f", *values)
        header[name] = {"dtype": "F32", "shape": shape, "data_offsets": [start, len(data)]}
    header["__metadata__"] = metadata
    text = json.dumps(header).encode()
    text += b" " * (-len(text) % 8)
    return struct.pack("<Q", len(text)) + text + data


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--channels", type=int, required=True, help="K, the scene's feature channels")
    ap.add_argument("--channel", type=int, default=0, help="the channel to colour (default 0)")
    ap.add_argument("--range", default="0,1", help="LO,HI mapped to the ends of the map")
    ap.add_argument("-o", "--output", required=True)
    a = ap.parse_args()
    lo, hi = (float(v) for v in a.range.split(","))
    if not (1 <= a.channels <= 64 and 0 <= a.channel < a.channels and hi > lo):
        sys.exit("error: need 1 <= --channels <= 64, 0 <= --channel < --channels, LO < HI")
    t = [lo + p * (hi - lo) for p, *_ in KNOTS]
    cols = [c for _, *c in KNOTS]
    n = len(KNOTS) - 1
    # Hidden j (0..n-1) = relu(f - t_j); colour(f) = c_0 + sum_j s_j relu(f - t_j), where
    # s_j is the change of slope at knot j.
    w1 = []
    for j in range(n):
        row = [0.0] * a.channels
        row[a.channel] = 1.0
        w1 += row
    b1 = [-t[j] for j in range(n)]
    slopes = [[(cols[j + 1][c] - cols[j][c]) / (t[j + 1] - t[j]) for c in range(3)] for j in range(n)]
    w2 = []
    for c in range(3):
        prev = 0.0
        for j in range(n):
            w2.append(slopes[j][c] - prev)
            prev = slopes[j][c]
    b2 = [cols[0][c] for c in range(3)]
    description = {
        "inputs": ["features"],
        "layers": [
            {"weight": "0.weight", "bias": "0.bias", "activation": "relu"},
            {"weight": "1.weight", "bias": "1.bias", "activation": "none"},
        ],
    }
    data = safetensors_bytes(
        [("0.weight", [n, a.channels], w1), ("0.bias", [n], b1),
         ("1.weight", [3, n], w2), ("1.bias", [3], b2)],
        {"verisplat_mlp": json.dumps(description)},
    )
    with open(a.output, "wb") as f:
        f.write(data)
    print(f"wrote {a.output}: channel {a.channel} of {a.channels}, {lo}..{hi} through a colour map")


if __name__ == "__main__":
    main()
