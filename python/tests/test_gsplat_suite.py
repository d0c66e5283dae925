"""gsplat 1.5.3's own test_rasterization.py, run through verisplat with the original 3DGS
rules instead of gsplat's (VERISPLAT_GSPLAT_SUITE=original; gsplat_suite/conftest.py does
the swap), must fail: the suite that tools/test.sh runs with gsplat's rules and expects to
pass can tell the two apart."""

import os
import pathlib
import subprocess
import sys

import pytest

if os.environ.get("VERISPLAT_REQUIRE_TORCH") != "1":
    pytest.importorskip("torch")
    pytest.importorskip("gsplat")

SUITE = pathlib.Path(__file__).resolve().parent / "gsplat_suite"
# The cheapest case: 3 images, RGB, direct colours, unpacked.
CASE = "test_rasterization.py::test_rasterization[batch_dims0-False-RGB-None-False]"


def run_suite(rules, *args):
    env = dict(os.environ, VERISPLAT_GSPLAT_SUITE=rules)
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
        cwd=SUITE, env=env, capture_output=True, text=True, timeout=900,
    )


def test_gsplats_rasterization_test_fails_with_the_original_rules():
    proc = run_suite("original", CASE)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1, out[-3000:]
    assert "1 failed" in out and "Mismatched elements" in out, out[-3000:]


def test_the_suite_refuses_unknown_rules():
    proc = run_suite("inria", "--collect-only")
    assert proc.returncode != 0
    assert "VERISPLAT_GSPLAT_SUITE='inria'" in proc.stdout + proc.stderr
