#!/usr/bin/env bash
# Fills fuzz/corpus/<target>/ with small seed inputs made from the project's real files
# (../shared/data, tests/data/cameras) and a few variants derived from them with Python's
# standard library. Nothing here is committed: the corpus is rebuilt by running this.
# Usage: fuzz/seeds.sh [DATA_DIR]   (DATA_DIR defaults to ../shared/data beside the repo)
set -euo pipefail
cd "$(dirname "$0")/.."
DATA="${1:-$(pwd)/../shared/data}"
[ -d "$DATA" ] || DATA=/work/shared/data
CAMS=tests/data/cameras
C=fuzz/corpus
mkdir -p $C/{ply,splat,spz,compressed_ply,sog_zip,sog_meta,detect,cameras_json,colmap_text,colmap_binary,nerfstudio,keyframes}

cp "$DATA/train3_sh3.ply" $C/ply/
cp "$DATA/train3.splat" $C/splat/
cp "$DATA/train3_sh3.v3.spz" $C/spz/
cp "$DATA/pc_test_64_sh3.compressed.ply" $C/compressed_ply/
cp fuzz/seeds/sog_zip/* $C/sog_zip/ 2>/dev/null || true
cp fuzz/seeds/sog_meta/* $C/sog_meta/
cp "$DATA/playbot_lod3_31k_sh2_sog/meta.json" $C/sog_meta/playbot_meta.json
cp "$DATA/plant_orbit_cameras.synthetic.json" $C/cameras_json/
cp $CAMS/nerfstudio_camera_path.json $C/nerfstudio/
cp $CAMS/keyframes_example.json $CAMS/keyframes_rotation.json $C/keyframes/
{ cat $CAMS/colmap_text/cameras.txt; printf '\0'; cat $CAMS/colmap_text/images.txt; } > $C/colmap_text/model

# Derived seeds: PLY in the other two encodings, SPZ v2 (gzip), bare v3 and v4 (zstd raw
# blocks), COLMAP binary from the text model.
python3 - "$DATA" "$C" "$CAMS" <<'PY'
import gzip, struct, sys
data, c, cams = sys.argv[1:4]

names = ["x","y","z","nx","ny","nz","f_dc_0","f_dc_1","f_dc_2","opacity",
         "scale_0","scale_1","scale_2","rot_0","rot_1","rot_2","rot_3"]
rows = [[0.1*i, -0.2*i, 1.0+i, 0,0,0, 0.5,-0.25,0.1, 1.5, -3,-3.5,-4, 1,0.1*i,0,0] for i in range(3)]
def header(fmt):
    h = f"ply\nformat {fmt} 1.0\nelement vertex {len(rows)}\n"
    h += "".join(f"property float {n}\n" for n in names)
    return (h + "end_header\n").encode()
open(f"{c}/ply/three_ascii.ply","wb").write(header("ascii") + b"".join(
    (" ".join(repr(float(v)) for v in r) + "\n").encode() for r in rows))
open(f"{c}/ply/three_be.ply","wb").write(header("binary_big_endian") + b"".join(
    struct.pack(">" + "f"*len(r), *r) for r in rows))
# A face element after the vertices, with a list property.
h = header("binary_little_endian").replace(b"end_header\n",
    b"element face 1\nproperty list uchar int vertex_indices\nend_header\n")
open(f"{c}/ply/three_face.ply","wb").write(h + b"".join(
    struct.pack("<" + "f"*len(r), *r) for r in rows) + struct.pack("<Biii", 3, 0, 1, 2))

# SPZ: payload of 2 Gaussians, SH degree 1.
n, deg = 2, 1
attrs = [bytes(range(9*n)), bytes([200, 30]), bytes([100,128,150]*n), bytes([90,100,110]*n)]
sh = bytes([128 + 5*k for k in range(9*n)])
def hdr(version, flags=0): return struct.pack("<IIIBBBB", 0x5053474e, version, n, deg, 12, flags, 0)
rot_v2 = bytes([127, 130, 140]*n)
rot_v3 = struct.pack("<II", 0x0, 0xC0000000 | 0x12345)
open(f"{c}/spz/two_v2.spz","wb").write(gzip.compress(hdr(2) + b"".join(attrs) + rot_v2 + sh))
open(f"{c}/spz/two_v3_bare.spz","wb").write(hdr(3) + b"".join(attrs) + rot_v3 + sh)
def zstd_raw(b):
    # Frame: magic, descriptor (single segment, 4-byte content size), one last raw block.
    return struct.pack("<IBI", 0xFD2FB528, 0xA0, len(b)) + struct.pack("<I", (len(b) << 3) | 1)[:3] + b
streams = [zstd_raw(s) for s in attrs + [rot_v3, sh]]
sizes = [len(s) for s in attrs + [rot_v3, sh]]
h4 = struct.pack("<IIIBBBBI12x", 0x5053474e, 4, n, deg, 12, 0, 6, 32)
toc = b"".join(struct.pack("<QQ", len(z), u) for z, u in zip(streams, sizes))
open(f"{c}/spz/two_v4.spz","wb").write(h4 + toc + b"".join(streams))

# COLMAP binary from the text model.
models = {"SIMPLE_PINHOLE": 0, "PINHOLE": 1}
cams_b = []
for line in open(f"{cams}/colmap_text/cameras.txt"):
    if line.startswith("#") or not line.strip(): continue
    f = line.split()
    cams_b.append(struct.pack("<iiQQ", int(f[0]), models[f[1]], int(f[2]), int(f[3]))
                  + b"".join(struct.pack("<d", float(p)) for p in f[4:]))
cams_bin = struct.pack("<Q", len(cams_b)) + b"".join(cams_b)
imgs, lines = [], [l for l in open(f"{cams}/colmap_text/images.txt") if not l.startswith("#")]
for i in range(0, len(lines) - 1, 2):
    f = lines[i].split()
    if not f: continue
    pts = lines[i + 1].split()
    p2d = [(float(pts[k]), float(pts[k+1]), int(pts[k+2])) for k in range(0, len(pts) - 2, 3)]
    imgs.append(struct.pack("<i7di", int(f[0]), *map(float, f[1:8]), int(f[8])) + f[9].encode() + b"\0"
                + struct.pack("<Q", len(p2d)) + b"".join(struct.pack("<ddq", *p) for p in p2d))
imgs_bin = struct.pack("<Q", len(imgs)) + b"".join(imgs)
open(f"{c}/colmap_binary/model","wb").write(struct.pack("<I", len(cams_bin)) + cams_bin + imgs_bin)
PY

# Content detection sees every scene seed.
for t in ply splat spz compressed_ply sog_zip; do cp $C/$t/* $C/detect/ 2>/dev/null || true; done
chmod -R u+w $C
echo "seeded: $(for d in $C/*/; do printf '%s=%s ' "$(basename $d)" "$(ls $d | wc -l)"; done)"
