"""The clustering's DBSCAN (clusters.dbscan, from scipy's k-d tree pairs) against scikit-learn's DBSCAN, its oracle:
the same labels, noise and cluster numbers, on generated blobs in 6 dimensions (position and scaled colour, as the
voxel centroids of a frame) with border points between touching clusters."""
from __future__ import annotations

import numpy as np
import pytest
from sklearn.cluster import DBSCAN

from perception_aruco.objects.clusters import dbscan


@pytest.mark.parametrize("seed", range(8))
def test_dbscan_labels_are_scikit_learns(seed):
    rng = np.random.default_rng(seed)
    blobs = [rng.normal(rng.uniform(0, 0.3, 6), rng.uniform(0.003, 0.012), (int(rng.integers(20, 400)), 6))
             for _ in range(int(rng.integers(3, 12)))]
    x = np.concatenate(blobs + [rng.uniform(0, 0.3, (200, 6))])   # touching blobs, scattered noise
    x = x[rng.permutation(len(x))]
    eps, min_samples = float(rng.uniform(0.006, 0.02)), int(rng.integers(3, 8))
    want = DBSCAN(eps=eps, min_samples=min_samples).fit(x).labels_
    got = dbscan(x, eps, min_samples)
    assert len(set(want)) > 2 and (want == -1).any()   # clusters and noise both present
    np.testing.assert_array_equal(got, want)
