"""vksplat.fit and Scene.evaluate_field (issue 26): a fit from numpy arrays, the field it
holds against the truth and against the scene saved and loaded again, units, and the
refusals."""

import warnings

import numpy as np
import pytest

import vksplat


def two_blobs(p):
    """A sum of two anisotropic Gaussians (the model class), two channels."""
    out = np.zeros((len(p), 2))
    for c, s, f in [((-0.4, 0.0, 0.1), (0.35, 0.2, 0.25), (1.0, 0.5)), ((0.5, 0.3, -0.2), (0.2, 0.3, 0.2), (0.7, -0.8))]:
        g = np.exp(-0.5 * (((p - np.array(c)) / np.array(s)) ** 2).sum(1))
        out += g[:, None] * np.array(f)
    return out


def samples(n, seed=1):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    return p, two_blobs(p).astype(np.float32)


def test_fit_returns_a_scene_whose_field_matches_the_samples(tmp_path):
    p, v = samples(3000)
    scene = vksplat.fit(p, v, steps=300)
    assert scene.feature_count == 2 and len(scene) == scene.fit_report["gaussians"]
    assert scene.fit_report["gaussians_initial"] == 150  # one per 20 samples
    err = scene.fit_report["holdout_relative_l2"]
    assert err < 0.15, err
    # The field at fresh points: relative L2 within 0.15 of the truth (the held-out
    # error is of the same kind).
    q, truth = samples(500, seed=7)
    f = scene.evaluate_field(q)
    assert f.shape == (500, 2) and f.dtype == np.float32
    rel = np.linalg.norm(f - truth) / np.linalg.norm(truth)
    assert rel < 0.15, rel
    # Saved and loaded, the PLY holds the same field.
    scene.save(tmp_path / "f.ply")
    again = vksplat.load(tmp_path / "f.ply").evaluate_field(q)
    np.testing.assert_allclose(again, f, rtol=0, atol=1e-6)


def test_units_do_not_matter_and_bad_inputs_are_refused():
    p, v = samples(1500)
    base = vksplat.fit(p, v, steps=150).fit_report["holdout_relative_l2"]
    small = vksplat.fit(p, v * 1e-9, steps=150)
    assert abs(small.fit_report["holdout_relative_l2"] - base) < 5e-3
    assert np.abs(small.features).max() < 1e-7  # the features carry the unit
    with pytest.raises(ValueError, match="lie at one point"):
        vksplat.fit(np.zeros((10, 3)), np.ones(10))
    with pytest.raises(ValueError, match="pass db=True"):
        vksplat.fit(p, -np.abs(v[:, 0]) - 50)
    with pytest.raises(ValueError, match="shape"):
        vksplat.fit(p, v[:10])
    with pytest.raises(ValueError, match="no feature channels"):
        vksplat.demo().evaluate_field(p[:3])
    rng = np.random.default_rng(3)
    noise = rng.choice([-1.0, 1.0], 600) * (1 + rng.uniform(size=600))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = vksplat.fit(rng.uniform(-1, 1, (600, 3)), noise, steps=100)
    assert any("no better than predicting 0" in str(w.message) for w in caught)
    assert s.fit_report["warnings"]
