"""gsplat 1.5.3's own test_rasterization.py and test_strategy.py (copied unmodified from
gsplat's repository at tag v1.5.3, Apache-2.0: LICENSE here) run through verisplat on the
CPU. They are collected only when VERISPLAT_GSPLAT_SUITE names the rules to run them with:

    VERISPLAT_GSPLAT_SUITE=gsplat   pytest python/tests/gsplat_suite    # must pass
    VERISPLAT_GSPLAT_SUITE=original pytest python/tests/gsplat_suite    # must fail

What this file swaps, gsplat's files untouched:
- `gsplat.rendering.rasterization` -> `verisplat.torch.rasterization(..., rules=<rules>)`
  (with "gsplat" that is `verisplat.gsplat.rasterization`, what users import);
- `gsplat.strategy.MCMCStrategy` -> `verisplat.gsplat.MCMCStrategy` (its CUDA kernels in
  torch); `DefaultStrategy` is gsplat's own either way;
- each test module's `device` ("cuda:0") -> the CPU, and `torch.cuda.is_available()` reads
  True while the two modules are imported, so their `skipif(no CUDA)` marks do not skip;
- the CUDA-only helpers of gsplat's torch reference (`_rasterization`) -> the CPU stand-ins
  of cpu_reference.py (checked against a brute-force compositor in test_cpu_reference.py).
Without the variable nothing is swapped and only our own tests here are collected.
"""

import os
import pathlib

import pytest

SUITE = ("test_rasterization.py", "test_strategy.py")
RULES = os.environ.get("VERISPLAT_GSPLAT_SUITE")

if RULES is None:
    collect_ignore = list(SUITE)
elif RULES not in ("gsplat", "original"):
    raise pytest.UsageError(
        f"VERISPLAT_GSPLAT_SUITE={RULES!r}: expected 'gsplat' or 'original' (the rules "
        "verisplat renders gsplat's test suite with)")
else:
    import functools

    import gsplat.cuda._torch_impl as gs_torch_impl
    import gsplat.cuda._wrapper as gs_wrapper
    import gsplat.rendering as gs_rendering
    import gsplat.strategy as gs_strategy
    import torch

    from gsplat_suite import cpu_reference
    import verisplat.gsplat
    import verisplat.torch

    gs_rendering.rasterization = functools.partial(verisplat.torch.rasterization, rules=RULES)
    gs_strategy.MCMCStrategy = verisplat.gsplat.MCMCStrategy
    gs_rendering.isect_tiles = cpu_reference.isect_tiles
    gs_rendering.isect_offset_encode = cpu_reference.isect_offset_encode
    gs_rendering.spherical_harmonics = cpu_reference.spherical_harmonics
    gs_wrapper.rasterize_to_indices_in_range = cpu_reference.rasterize_to_indices_in_range
    gs_torch_impl.accumulate = cpu_reference.accumulate

    HERE = pathlib.Path(__file__).resolve().parent

    @pytest.hookimpl(wrapper=True)
    def pytest_make_collect_report(collector):
        # gsplat's modules evaluate `skipif(not torch.cuda.is_available())` on import.
        path = getattr(collector, "path", None)
        if not (isinstance(collector, pytest.Module) and path is not None
                and path.parent == HERE and path.name in SUITE):
            return (yield)
        real = torch.cuda.is_available
        torch.cuda.is_available = lambda: True
        try:
            return (yield)
        finally:
            torch.cuda.is_available = real

    @pytest.fixture(autouse=True)
    def _gsplat_device_is_the_cpu(request, monkeypatch):
        if request.module.__file__ and pathlib.Path(request.module.__file__).name in SUITE:
            monkeypatch.setattr(request.module, "device", torch.device("cpu"))
