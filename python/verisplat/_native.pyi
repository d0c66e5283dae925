"""Type stubs of verisplat's compiled module (the public API is the `verisplat` package)."""

from typing import Any, Dict, List, Optional, Sequence, Tuple

# A lens: its kind (pinhole, distorted, fisheye, orthographic, equirectangular) and numbers.
LensTuple = Tuple[str, Sequence[float]]
CamTuple = Tuple[str, int, int, Sequence[float], Sequence[float], LensTuple]
# background, sh_degree, scale_modifier, max_scale, min_opacity, antialiased, kernel, rules,
# near plane, reproducible
Options = Tuple[
    Sequence[float], Optional[int], float, Optional[float], Optional[float], Optional[bool],
    Optional[str], Optional[str], Optional[float], bool,
]
Planes = Tuple[Optional[bytearray], Optional[bytearray], Optional[bytearray], Optional[bytearray]]

__version__: str

# The renderer's rule constants (python/src/rules.rs: src/rules.rs, src/model/sh.rs); each
# float the shortest decimal of the crate's f32.
NEAR_PLANE: float
COV2D_DILATION: float
ANTIALIAS_MIN_RATIO: float
ALPHA_MAX: float
ALPHA_MIN: float
T_MIN: float
GSPLAT_NEAR_PLANE: float
GSPLAT_ALPHA_MAX: float
GSPLAT_EXTEND: float
SH_C0: float
SH_C1: float
SH_C2: Tuple[float, float, float, float, float]
SH_C3: Tuple[float, float, float, float, float, float, float]
TILE_SIZE: int
BACKWARD_CHANNELS: int
MAX_FEATURES: int

class Scene:
    def __len__(self) -> int: ...
    @property
    def sh_degree(self) -> int: ...
    @property
    def antialiased(self) -> bool: ...
    @property
    def source(self) -> str: ...
    @property
    def feature_count(self) -> int: ...
    @property
    def kernel(self) -> str: ...
    @property
    def rules(self) -> str: ...
    @property
    def id(self) -> int: ...
    def array(self, name: str) -> bytes: ...
    def save(self, path: str, overwrite: bool = False, spz_axes: str = "spec") -> None: ...
    def filtered(
        self,
        max_scale: Optional[float] = None,
        min_opacity: Optional[float] = None,
        sh_degree: Optional[int] = None,
    ) -> "Scene": ...
    def evaluate_field(self, points: bytes, n: int, times: Optional[bytes] = None) -> bytearray: ...
    @property
    def time_range(self) -> Optional[Tuple[float, float]]: ...
    def at_time(self, t: float) -> "Scene": ...

class Renderer:
    def __init__(self, device: Optional[str] = None) -> None: ...
    @property
    def device(self) -> str: ...
    @property
    def timings(self) -> Dict[str, float]: ...
    @property
    def counters(self) -> Dict[str, int]: ...
    def render(
        self,
        scene: Scene,
        cameras: List[CamTuple],
        options: Options,
        want: Tuple[bool, bool, bool, bool, Optional[str]],
    ) -> Planes: ...

def load(path: str, iteration: Optional[int] = None, spz_axes: str = "spec") -> Scene: ...
def demo() -> Scene: ...
def fit(
    points: bytes,
    values: bytes,
    n: int,
    k: int,
    gaussians: Optional[int] = None,
    max_gaussians: Optional[int] = None,
    steps: int = 1500,
    kernel: str = "gaussian",
    holdout: float = 0.1,
    seed: int = 1,
    bounds: Optional[Sequence[float]] = None,
    magnitude_channel: int = 0,
    db: bool = False,
    clip_grad: float = 0.0,
    times: Optional[bytes] = None,
) -> Tuple[Scene, Dict[str, object]]: ...
def scene_from_arrays(
    n: int,
    sh_coeffs: int,
    means: bytes,
    quats: bytes,
    scales: bytes,
    opacities: bytes,
    sh: bytes,
    activated: bool,
    antialiased: bool = False,
    feature_count: int = 0,
    features: Optional[bytes] = None,
) -> Scene: ...
def load_cameras(path: str, frames: Optional[int] = None, fps: Optional[float] = None) -> List[CamTuple]: ...
def save_cameras(path: str, cameras: List[CamTuple], overwrite: bool = False) -> None: ...
def orbit(
    scene: Scene,
    frames: int,
    width: int,
    height: int,
    vfov: float,
    elevation: float,
    start: float,
    up: Sequence[float],
    centre: Optional[Sequence[float]] = None,
    radius: Optional[float] = None,
) -> List[CamTuple]: ...
def default_camera(scene: Scene, width: int, height: int) -> CamTuple: ...
def check_lens(lens: LensTuple) -> None: ...
def fisheye_max_theta(k: Sequence[float]) -> float: ...
def look_at(
    eye: Sequence[float],
    target: Sequence[float],
    up: Sequence[float],
    width: int,
    height: int,
    vfov: float,
    name: str = "",
) -> CamTuple: ...
def bulk_centre(scene: Scene) -> List[float]: ...
def render_cpu(
    scene: Scene,
    cameras: List[CamTuple],
    options: Options,
    want: Tuple[bool, bool, bool, bool, Optional[str]],
) -> Planes: ...
def read_image(path: str) -> Tuple[int, int, List[str], bytearray]: ...
def compare(
    reference: bytes, test: bytes, width: int, height: int, channels: int, kind: str
) -> Dict[str, Optional[float]]: ...
def encode_png(rgb: bytes, width: int, height: int) -> bytes: ...
def save_image(
    path: str,
    rgb: bytes,
    alpha: Optional[bytes],
    depth: Optional[bytes],
    width: int,
    height: int,
    png16: bool,
    overwrite: bool,
) -> None: ...

# Differentiable rasterization (verisplat.raster, verisplat.torch).
# (N, means, quats, scales, opacities, colors as f32 bytes, sh_degree or None, channels)
ParamsTuple = Tuple[int, bytes, bytes, bytes, bytes, bytes, Optional[int], int]

class Rasterizer:
    def __init__(self, device: Optional[str] = None, validation: bool = False) -> None: ...
    @property
    def device(self) -> str: ...
    @property
    def stats(self) -> Dict[str, int]: ...
    @property
    def timings(self) -> Dict[str, float]: ...
    def set_accumulation(self, mode: str) -> None: ...
    def forward(
        self,
        params: ParamsTuple,
        camera: CamTuple,
        background: List[float],
        kernel: str,
        shader: Optional[bytes] = None,
        antialiased: bool = False,
        rules: str = "original",
        near_plane: Optional[float] = None,
        reproducible: bool = False,
    ) -> Tuple[bytearray, bytearray, bytearray, int, bytearray]: ...
    def backward(
        self,
        params: ParamsTuple,
        camera: CamTuple,
        background: List[float],
        kernel: str,
        token: int,
        grad_color: Optional[bytes] = None,
        grad_alpha: Optional[bytes] = None,
        grad_depth: Optional[bytes] = None,
        shader: Optional[bytes] = None,
        screen: bool = False,
        antialiased: bool = False,
        rules: str = "original",
        near_plane: Optional[float] = None,
        reproducible: bool = False,
    ) -> Dict[str, Any]: ...

def reference_forward(
    params: ParamsTuple,
    camera: CamTuple,
    background: List[float],
    kernel: str,
    shader: Optional[bytes] = None,
    antialiased: bool = False,
    rules: str = "original",
    near_plane: Optional[float] = None,
) -> Tuple[bytearray, bytearray, bytearray]: ...
def reference_backward(
    params: ParamsTuple,
    camera: CamTuple,
    background: List[float],
    kernel: str,
    grad_color: Optional[bytes] = None,
    grad_alpha: Optional[bytes] = None,
    grad_depth: Optional[bytes] = None,
    shader: Optional[bytes] = None,
    antialiased: bool = False,
    rules: str = "original",
    near_plane: Optional[float] = None,
) -> Dict[str, Any]: ...

LayerTuple = Tuple[int, int, bytes, bytes, str]

def shader_from_layers(inputs: List[str], layers: List[LayerTuple]) -> bytearray: ...
def shader_file(path: str) -> bytearray: ...
def shader_layers(data: bytes) -> Tuple[List[str], List[LayerTuple]]: ...
