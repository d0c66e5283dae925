"""Times a fast drag of the notebook turntable (BENCHMARKS.md, issue 29 item 8): 30 mouse
moves at 60 Hz on the 31k robot at 512x512, then a mouse-up. Needs the notebook extra."""
import pathlib
import time

import verisplat
from verisplat import widgets
DATA = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"
scene = verisplat.load(DATA / "playbot_lod3_31k_sh2.ply")
r = verisplat.Renderer()
tt = widgets.Turntable(scene, width=512, height=512, renderer=r)
tt.render(); t0=time.perf_counter(); tt.render(); one=time.perf_counter()-t0
f0 = tt.frames
tt._handle_event({"type": "mousedown", "relativeX": 0, "relativeY": 50, "buttons": 1})
t0 = time.perf_counter()
for k in range(1, 31):
    tt._handle_event({"type": "mousemove", "relativeX": 3*k, "relativeY": 50, "buttons": 1})
    time.sleep(0.016)  # a 60 Hz mouse
h = time.perf_counter() - t0
tt._handle_event({"type": "mouseup", "relativeX": 90, "relativeY": 50})
if hasattr(tt, "wait"): tt.wait()
rest = time.perf_counter() - t0
print(f"one full render {one*1e3:.0f} ms; 30 moves at 60 Hz: handlers done after {h:.2f} s, view at rest after {rest:.2f} s, {tt.frames-f0} frames drawn ({getattr(tt,'previews',0)} previews, last preview {getattr(tt,'preview_size',None)})")
