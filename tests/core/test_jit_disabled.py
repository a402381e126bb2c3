"""The compiled kernels are the implementation; with NUMBA_DISABLE_JIT=1 the same
source runs as plain Python (for debugging) and must give the same numbers."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np

SCRIPT = textwrap.dedent(
    """
    import sys
    import numpy as np
    from sim.motion import stationary
    from mavins.core.runner import navigate
    m = stationary(45.0, 100.0, 1.0, 2.0, 30.0, 0.01, 300)
    init = dict(t=0, lat=45, lon=8, h=100, vn=1, ve=0, vd=0, roll=1, pitch=2, yaw=30)
    a = navigate(m.t, m.dtheta, m.dv, init, samples=3)
    b = navigate(m.t, m.dtheta / 0.01, m.dv / 0.01, init, data="rates", imu_rates="sampled", samples=2,
                 attitude="dcm", order="3", position="simpson")
    np.save(sys.argv[1], np.concatenate([a.ravel(), b.ravel()]))
    """
)


def _run(tmp_path, disable: bool) -> np.ndarray:
    out = tmp_path / f"{'nojit' if disable else 'jit'}.npy"
    env = dict(os.environ)
    if disable:
        env["NUMBA_DISABLE_JIT"] = "1"
    else:
        env.pop("NUMBA_DISABLE_JIT", None)
    subprocess.run([sys.executable, "-c", SCRIPT, str(out)], check=True, env=env, timeout=300)
    return np.load(out)


def test_same_source_runs_without_jit(tmp_path):
    compiled = _run(tmp_path, disable=False)
    python = _run(tmp_path, disable=True)
    assert compiled.shape == python.shape and compiled.size > 1000
    # same operations; only libm vs LLVM intrinsics may differ in the last bits
    np.testing.assert_allclose(python, compiled, rtol=0, atol=1e-12)
