"""The BVH builder (iblbake/scene/bvh.py build_bvh): a valid tree whatever the input, split
where the surface area heuristic says, its depth bounded for the kernels' traversal stack. The
kernels' traversal of it is checked against the brute-force twin in test_render*.py."""

import numpy as np
import pytest

from iblbake.scene import bvh as bvh_module
from iblbake.scene.bvh import LEAF_SIZE, SAH_DEPTH, build_bvh


def _check_tree(bvh, lo, hi, leaf_size):
    ints = bvh.nodes.view(np.int32)
    leaf = ints[:, 7] > 0
    assert sorted(bvh.order.tolist()) == list(range(len(lo)))
    assert ints[leaf, 7].sum() == len(lo) and ints[leaf, 7].max() <= leaf_size
    for i in range(len(bvh.nodes)):
        if leaf[i]:
            f, c = ints[i, 3], ints[i, 7]
            prims = bvh.order[f:f + c]
            # the nodes are float32 rounded to nearest, which keeps the order of the rounded bounds
            # (triangle_bounds pads each triangle's box for the float32 corners the device sees)
            assert (lo[prims].astype(np.float32) >= bvh.nodes[i, 0:3]).all()
            assert (hi[prims].astype(np.float32) <= bvh.nodes[i, 4:7]).all()
        else:
            for k in (ints[i, 3], ints[i, 3] + 1):       # children inside their parent
                assert (bvh.nodes[k, 0:3] >= bvh.nodes[i, 0:3]).all() and (bvh.nodes[k, 4:7] <= bvh.nodes[i, 4:7]).all()


@pytest.mark.parametrize("n", [1, 2, 5, 37, 1000])
def test_random_boxes_give_a_valid_tree(n):
    rng = np.random.default_rng(n)
    lo = rng.normal(size=(n, 3)) * [10, 1, 0.1]
    hi = lo + rng.random((n, 3)) * 0.5
    bvh = build_bvh(lo, hi)
    _check_tree(bvh, lo, hi, LEAF_SIZE)


def test_root_splits_between_clusters_not_at_the_median():
    """10 boxes at x ~ 0 and 90 at x ~ 100: the SAH cut is between the clusters (10 | 90), where
    the object median would cut the large cluster (50 | 50)."""
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.random(10), 100 + rng.random(90)])
    lo = np.stack([x, rng.random(100), rng.random(100)], axis=1)
    hi = lo + 0.01
    bvh = build_bvh(lo, hi)
    ints = bvh.nodes.view(np.int32)
    left = ints[0, 3]
    assert bvh.nodes[left, 4] < 2.0 and bvh.nodes[left + 1, 0] > 99.0     # one cluster per child
    _check_tree(bvh, lo, hi, LEAF_SIZE)


def test_past_sah_depth_the_median_bounds_the_depth(monkeypatch):
    """Past SAH_DEPTH levels every node splits at its object median, so the depth is at most
    SAH_DEPTH + log2(n / leaf size) + 1 whatever the SAH did above (the kernels' stack holds 62)."""
    n = 5000
    rng = np.random.default_rng(5)
    lo = rng.random((n, 3)) ** 8 * 100          # crowded near 0, sparse far out: uneven SAH cuts
    hi = lo + 0.001
    assert SAH_DEPTH + int(np.ceil(np.log2(2 ** 31 / LEAF_SIZE))) + 1 <= 62
    for depth in (0, 3):
        monkeypatch.setattr(bvh_module, "SAH_DEPTH", depth)
        bvh = build_bvh(lo, hi)
        assert bvh.depth <= depth + int(np.ceil(np.log2(n / LEAF_SIZE))) + 1
        _check_tree(bvh, lo, hi, LEAF_SIZE)
