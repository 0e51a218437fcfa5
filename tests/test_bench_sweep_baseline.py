"""The batched baseline of ``workbench bench sweep`` (workbench.bench.baselines_sweep):
its matrix exponential against scipy's, and its map against the point-by-point loop."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from workbench.bench.baselines_sweep import BatchedMap, expm_batched, pointwise_rho


def test_expm_batched_is_exact_on_symmetric_matrices():
    # M = Q diag(d) Q' has exp(M) = Q diag(exp(d)) Q' (Q orthogonal: computed to ~1e-15)
    rng = np.random.default_rng(3)
    Ms, refs = [], []
    for scale in np.logspace(-3, 1.3, 30):            # 0 to 7 squarings
        Q, _ = np.linalg.qr(rng.standard_normal((5, 5)))
        d = scale * rng.standard_normal(5)
        Ms.append(Q @ np.diag(d) @ Q.T)
        refs.append(Q @ np.diag(np.exp(d)) @ Q.T)
    E = expm_batched(np.array(Ms))
    for k, ref in enumerate(refs):
        # rounding doubles at most with each squaring: 2^7 * 1e-15 ~ 1e-13 of the largest entry
        assert np.max(np.abs(E[k] - ref)) <= 2e-13 * np.max(np.abs(ref)), k


def test_expm_batched_matches_scipy():
    rng = np.random.default_rng(3)
    # 1-norms up to ~15 (the map's state-scaled ZOH matrices are about 2), and zero
    M = rng.standard_normal((40, 5, 5)) * np.logspace(-3, 0.5, 40)[:, None, None]
    M[0] = 0.0
    E = expm_batched(M)
    for k in range(len(M)):
        ref = expm(M[k])
        # two scaling-and-squaring codes (different orders and scalings): each within
        # ~2^s eps of the largest entry; 1e-12 leaves a factor 10 of room
        assert np.max(np.abs(E[k] - ref)) <= 1e-12 * max(1.0, np.max(np.abs(ref))), k


@pytest.mark.parametrize("compile_c", [False])
def test_batched_map_matches_the_point_loop(compile_c):
    from pathlib import Path

    from workbench.controllers import from_plant
    from workbench.plant import Plant
    root = Path(__file__).resolve().parents[1]
    plant = Plant.from_toml(root / "designs" / "plants" / "situm_rodless_nominal.toml")
    ctrl = from_plant(plant)
    x = np.array([0.05, 0.2, 0.45, 0.3])
    ps = np.array([3e5, 5e5, 7e5, 4.2e5])
    rho = BatchedMap(plant, ctrl, len(x), compile_c=compile_c)(x, ps)
    # the loop solves each equilibrium with the workbench's operating_point and takes
    # scipy's expm of the unscaled matrices: an independent path to the same numbers;
    # 1e-9 is rounding in the equilibrium solve and the eigenvalues
    ref = pointwise_rho(plant, x, ps, ctrl)
    assert np.all(np.abs(rho - ref) < 1e-9)
    assert np.all((rho > 0.5) & (rho < 1.5))
