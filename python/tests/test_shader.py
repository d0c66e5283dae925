"""A neural shader (verisplat.raster.Shader) through the numpy-level differentiable
rasterizer: the device's gradients (Gaussians and every layer of the network) against the
f64 CPU reference, bit-identical run after run, files written and read back, clear errors,
and a shader learned from images. No torch needed."""

import numpy as np
import pytest

import verisplat
from verisplat import raster

W, H = 64, 48
K = 6


def gaussians(n=40, seed=0, k=K):
    rng = np.random.default_rng(seed)
    return dict(
        means=rng.uniform(-1, 1, (n, 3)).astype(np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
        scales=rng.uniform(0.08, 0.3, (n, 3)).astype(np.float32),
        opacities=rng.uniform(0.3, 0.95, n).astype(np.float32),
        colors=rng.normal(size=(n, k)).astype(np.float32),
    )


def network(seed=1, k=K, inputs=("features", "view_dir", "alpha"), hidden=12):
    rng = np.random.default_rng(seed)
    width = k + (3 if "view_dir" in inputs else 0) + (1 if "alpha" in inputs else 0)
    layers = []
    for i, o, act in [(width, hidden, "tanh"), (hidden, 3, "sigmoid")]:
        layers.append(
            (rng.uniform(-0.8, 0.8, (o, i)).astype(np.float32),
             rng.uniform(-0.3, 0.3, o).astype(np.float32), act)
        )
    return raster.Shader(layers, inputs)


def camera():
    return verisplat.look_at(eye=(0.3, -0.2, -4.0), target=(0, 0, 0), width=W, height=H)


def rel(a, b):
    a, b = np.asarray(a, np.float64).ravel(), np.asarray(b, np.float64).ravel()
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def test_shaded_gradients_on_the_device_equal_the_reference():
    s, cam, shader = gaussians(), camera(), network()
    bg = np.array([0.2, 0.1, 0.4], np.float32)
    args = dict(viewmat=cam.viewmat, K=cam.K, width=W, height=H, background=bg, shader=shader)
    ref = raster.Rasterizer(backend="reference")
    f = ref.forward(**s, **args)
    assert f.colors.shape == (H, W, 3)
    grad = np.random.default_rng(2).normal(size=(H, W, 3)).astype(np.float32)
    g = ref.backward(f, grad_colors=grad, grad_alphas=0.3 * grad[..., 0])
    r = raster.Rasterizer()
    fv = r.forward(**s, **args)
    assert np.abs(fv.colors - f.colors).max() < 1e-4
    gv = r.backward(fv, grad_colors=grad, grad_alphas=0.3 * grad[..., 0])
    for k in ["means", "quats", "scales", "opacities", "colors"]:
        assert rel(gv[k], g[k]) <= 1e-3, k
    assert gv["colors"].shape == (40, K)
    for name in ("shader_weights", "shader_biases"):
        assert len(gv[name]) == len(shader.layers)
        for layer, (a, b) in enumerate(zip(gv[name], g[name])):
            assert a.shape == b.shape
            assert np.abs(b).max() > 0, (name, layer)
            assert rel(a, b) <= 1e-3, (name, layer)
    # Bit-identical again.
    again = r.backward(r.forward(**s, **args), grad_colors=grad, grad_alphas=0.3 * grad[..., 0])
    for name in ("means", "colors", "opacities"):
        assert np.array_equal(again[name], gv[name])
    for a, b in zip(again["shader_weights"], gv["shader_weights"]):
        assert np.array_equal(a, b)


def test_a_shader_saves_and_loads_and_bad_ones_are_value_errors(tmp_path):
    shader = network(inputs=("features",))
    path = tmp_path / "shader.safetensors"
    shader.save(path)
    back = raster.Shader.load(path)
    assert back.inputs == ("features",)
    for (w, b, act), (w2, b2, act2) in zip(shader.layers, back.layers):
        assert np.array_equal(w, w2) and np.array_equal(b, b2) and act == act2
    with pytest.raises(FileExistsError):
        shader.save(path)
    w, b, _ = shader.layers[0]
    with pytest.raises(ValueError, match="3"):
        raster.Shader([(w, b, "relu")])  # 12 outputs, not 3
    with pytest.raises(ValueError, match="activation"):
        raster.Shader([(np.ones((3, K), np.float32), np.zeros(3, np.float32), "gelu")])
    with pytest.raises(ValueError, match="finite"):
        raster.Shader([(np.full((3, K), np.nan, np.float32), np.zeros(3, np.float32), "none")])
    s, cam = gaussians(k=4), camera()
    with pytest.raises(ValueError, match="feature channels"):
        raster.Rasterizer().forward(**s, viewmat=cam.viewmat, K=cam.K, width=W, height=H,
                                    shader=shader)


def test_a_shader_is_learned_from_images():
    """Gradient descent on the network's weights (Gaussians fixed) towards the images of
    another network lowers the loss by more than half."""
    s, cam = gaussians(n=60, seed=5), camera()
    target_shader = network(seed=7, inputs=("features",))
    args = dict(viewmat=cam.viewmat, K=cam.K, width=W, height=H)
    r = raster.Rasterizer()
    target = r.forward(**s, **args, shader=target_shader).colors.copy()
    layers = [(w.copy(), b.copy(), act) for w, b, act in network(seed=8, inputs=("features",)).layers]
    losses = []
    lr = 2.0
    for _ in range(60):
        shader = raster.Shader(layers, ("features",))
        f = r.forward(**s, **args, shader=shader)
        diff = f.colors - target
        losses.append(float(np.mean(diff**2)))
        g = r.backward(f, grad_colors=2 * diff / diff.size)
        layers = [
            (w - lr * gw, b - lr * gb, act)
            for (w, b, act), gw, gb in zip(layers, g["shader_weights"], g["shader_biases"])
        ]
    assert losses[-1] < 0.5 * losses[0], losses
