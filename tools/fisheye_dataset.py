#!/usr/bin/env python3
"""A fisheye data set with a known answer (issue 49): a scene rendered through an
equidistant fisheye (COLMAP OPENCV_FISHEYE, k1..k4 = 0) from rings of cameras on a sphere
around it, written as a COLMAP data set (images/*.png, sparse/0/*.txt with the scene's
centres as points3D) that `verisplat train` reads.

    tools/fisheye_dataset.py ../shared/data/playbot_lod3_31k_sh2.ply /tmp/fish180
    verisplat train /tmp/fish180 -o /tmp/fish180_model --eval --iterations 2000

The field of view spans the shorter side (--fov, default 180 degrees); every ray up to
180 degrees from the axis is imaged (the lens's max_theta is pi), as COLMAP's
OPENCV_FISHEYE reads back, so every pixel of the photo, the corners past 90 degrees
included, is the scene's and the trained camera sees what the photo saw. A 180-degree
fisheye has no pinhole view (`train --undistort` refuses it); --fov 120 has one.

The cameras are written to DIR/rig.json (an INRIA cameras.json with each camera's lens),
then `verisplat render SCENE --cameras DIR/rig.json --export-colmap DIR` renders them (on
the device). By default the rings are at 10, 35 and 60 degrees of elevation with 16, 12
and 8 cameras, looking at the centre `render --orbit` looks at (the centre of the scene's
2-98 % box, `bulk.box_2_98.centre` of `verisplat info --json`) from 1.3 times its 95 %
radius; world up is -y, as in the INRIA/COLMAP captures. When verisplat fails (a scene it
cannot read, an output that exists without --overwrite), its one-sentence error is the
script's, with a non-zero exit.
"""
import argparse
import json
import math
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]


def normalise(v):
    n = math.sqrt(sum(x * x for x in v))
    return [x / n for x in v]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def look_at(eye, target, down=(0.0, 1.0, 0.0)):
    """The camera-to-world rotation (rows; columns right, down, forward: OpenCV axes) of a
    camera at `eye` looking at `target` with world down `down` (up is -y)."""
    forward = normalise([t - e for t, e in zip(target, eye)])
    right = normalise(cross(down, forward))
    cam_down = cross(forward, right)
    return [[right[i], cam_down[i], forward[i]] for i in range(3)]


class Failed(Exception):
    """A verisplat command failed; it printed its own sentence on stderr."""

    def __init__(self, status):
        super().__init__(status)
        self.status = status


def run(cmd, capture=False):
    """Runs a verisplat command, its stderr passed through; its stdout when `capture`.
    A failure raises Failed with the command's exit status (its sentence already printed)."""
    try:
        done = subprocess.run(cmd, stdout=subprocess.PIPE if capture else None, text=True)
    except OSError as e:
        print(f"error: cannot run {cmd[0]}: {e} (build it, or pass --verisplat)", file=sys.stderr)
        raise Failed(2) from None
    if done.returncode != 0:
        raise Failed(done.returncode)
    return done.stdout


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="a 3DGS scene (e.g. ../shared/data/playbot_lod3_31k_sh2.ply)")
    p.add_argument("out", help="the data set directory to write")
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--fov", type=float, default=180.0, help="degrees across the shorter side")
    p.add_argument("--rings", default="10:16,35:12,60:8", help="ELEVATION_DEG:CAMERAS,...")
    p.add_argument("--radius", type=float, help="distance from the centre (default 1.3 x the 95 %% radius)")
    p.add_argument("--centre", help="X,Y,Z looked at (default: what render --orbit looks at)")
    p.add_argument("--verisplat", default=str(ROOT / "target" / "release" / "verisplat"))
    p.add_argument("--overwrite", action="store_true")
    a = p.parse_args()

    info = json.loads(run([a.verisplat, "info", a.scene, "--json"], capture=True))
    # The orbits' centre, as the binary computes it (not the per-axis median).
    centre = [float(x) for x in a.centre.split(",")] if a.centre else info["bulk"]["box_2_98"]["centre"]
    radius = a.radius or 1.3 * info["bulk"]["radius_95"]
    f = min(a.width, a.height) / 2.0 / math.radians(a.fov / 2.0)
    lens = {"kind": "fisheye", "k": [0.0, 0.0, 0.0, 0.0], "max_theta": math.pi}
    cams = []
    for r, ring in enumerate(a.rings.split(",")):
        elevation, count = ring.split(":")
        el = math.radians(float(elevation))
        for k in range(int(count)):
            # Rings start half a step apart, so no two rings share an azimuth.
            az = 2.0 * math.pi * (k + 0.5 * (r % 2)) / int(count)
            eye = [
                centre[0] + radius * math.cos(el) * math.sin(az),
                centre[1] - radius * math.sin(el),
                centre[2] - radius * math.cos(el) * math.cos(az),
            ]
            cams.append(
                {
                    "id": len(cams),
                    "img_name": f"fish_{len(cams):03d}",
                    "width": a.width,
                    "height": a.height,
                    "position": eye,
                    "rotation": look_at(eye, centre),
                    "fx": f,
                    "fy": f,
                    "lens": lens,
                }
            )
    out = pathlib.Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rig = out / "rig.json"
    if rig.exists() and not a.overwrite:
        print(f"error: {rig}: already exists; pass --overwrite to replace it", file=sys.stderr)
        return 1
    rig.write_text(json.dumps(cams, indent=1) + "\n")
    cmd = [a.verisplat, "render", a.scene, "--cameras", str(rig), "--export-colmap", str(out), "-q"]
    if a.overwrite:
        cmd.append("--overwrite")
    run(cmd)
    print(
        f"{out}: {len(cams)} fisheye photos of {a.width}x{a.height}, {a.fov:g} degrees across "
        f"the shorter side (f = {f:.2f} px), {radius:.3f} from ({centre[0]:.3f}, {centre[1]:.3f}, {centre[2]:.3f})"
    )


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Failed as e:
        sys.exit(e.status)
