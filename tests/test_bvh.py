"""The BVH builder (iblbake/scene/bvh.py build_bvh): a valid tree whatever the input, split
where the surface area heuristic says, its depth bounded for the kernels' traversal stack. The
kernels' traversal of it is checked against the brute-force twin in test_render*.py."""

import numpy as np
import pytest

from iblbake.scene import bvh as bvh_module
from iblbake.scene.bvh import LEAF_SIZE, SAH_DEPTH, WIDTH, build_bvh, device_tree
from iblbake.scene.layout import BVH_STACK, FLOAT4S


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
    SAH_DEPTH + log2(n / leaf size) + 1 whatever the SAH did above (62 at most: the wide tree's
    31 levels fit the kernels' stack, test below)."""
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


def _check_device_tree(bvh, v0, v1, v2):
    """The records the kernels traverse (device_tree): from the root every primitive is reached
    exactly once, each child's box holds everything under it, each leaf's lanes are its triangles'
    corners (zero past its count), and the depth fits the traversal stack."""
    rec = device_tree(bvh, v0[bvh.order], v1[bvh.order], v2[bvh.order])
    ints = rec.view(np.int32)
    n_nodes = len(bvh.wide)
    assert rec.shape == (n_nodes * FLOAT4S["BVH4_NODE"] + len(bvh.leaves) * FLOAT4S["BVH4_LEAF"], 4)
    lo, hi = np.minimum(np.minimum(v0, v1), v2), np.maximum(np.maximum(v0, v1), v2)
    seen = np.zeros(len(v0), int)
    depth = 0

    def visit(code, box_lo, box_hi, level):
        nonlocal depth
        depth = max(depth, level)
        if code < 0:
            off = -1 - code
            leaves_at = n_nodes * FLOAT4S["BVH4_NODE"]
            assert off >= leaves_at and (off - leaves_at) % FLOAT4S["BVH4_LEAF"] == 0
            first, count = ints[off + 9, 0], ints[off + 9, 1]
            assert 1 <= count <= WIDTH
            prims = bvh.order[first:first + count]
            seen[prims] += 1
            assert (lo[prims].astype(np.float32) >= box_lo).all() and (hi[prims].astype(np.float32) <= box_hi).all()
            for c, v in enumerate((v0, v1, v2)):
                lanes = rec[off + 3 * c:off + 3 * c + 3].T          # (lane, xyz)
                np.testing.assert_array_equal(lanes[:count], v[prims].astype(np.float32))
                assert (lanes[count:] == 0).all()
            return
        base = FLOAT4S["BVH4_NODE"] * code
        for j in range(WIDTH):
            clo, chi = rec[base:base + 3, j], rec[base + 3:base + 6, j]
            if np.isinf(clo).all() and (clo > 0).all():
                assert (chi < 0).all() and np.isinf(chi).all()        # an empty child: a box no ray meets
                continue
            assert (clo >= box_lo).all() and (chi <= box_hi).all()
            visit(int(ints[base + 6, j]), clo, chi, level + 1)

    visit(0, np.full(3, -np.inf, np.float32), np.full(3, np.inf, np.float32), 0)
    assert (seen == 1).all()
    assert depth == bvh.wide_depth and (WIDTH - 1) * depth + 1 <= BVH_STACK


@pytest.mark.parametrize("n", [1, 2, 3, 5, 37, 1000])
def test_the_kernels_wide_tree_holds_every_triangle_once(n):
    rng = np.random.default_rng(10 + n)
    v0 = rng.normal(size=(n, 3)) * [10, 1, 0.1]
    v1, v2 = v0 + rng.random((n, 3)), v0 + rng.random((n, 3))
    bvh = build_bvh(np.minimum(np.minimum(v0, v1), v2), np.maximum(np.maximum(v0, v1), v2))
    _check_device_tree(bvh, v0, v1, v2)


def test_the_wide_tree_of_the_deepest_binary_tree_fits_the_stack(monkeypatch):
    """The binary tree's depth bound (SAH_DEPTH + log2(2^31 / leaf size) + 1 levels) halves in
    the wide tree (each of its levels two of the binary's from the root), whose traversal stack
    then holds a node's four children at every level."""
    binary = SAH_DEPTH + int(np.ceil(np.log2(2 ** 31 / LEAF_SIZE))) + 1
    assert (WIDTH - 1) * (binary // 2) + 1 <= BVH_STACK
    n = 3000
    rng = np.random.default_rng(7)
    v0 = rng.random((n, 3)) ** 8 * 100
    v1, v2 = v0 + 0.001, v0 + [0.001, 0, 0.002]
    monkeypatch.setattr(bvh_module, "SAH_DEPTH", 2)
    bvh = build_bvh(np.minimum(np.minimum(v0, v1), v2), np.maximum(np.maximum(v0, v1), v2))
    assert bvh.wide_depth == max(1, bvh.depth // 2)
    _check_device_tree(bvh, v0, v1, v2)


@pytest.mark.parametrize("mend", ["child past the nodes", "leaf past the triangles", "wide leaf record",
                                  "closed of another mesh", "report without the wide count"])
def test_a_cached_geometry_entry_that_does_not_read_back_is_built_again(tmp_path, mend):
    """A geometry entry whose files match its manifest but would send a traversal outside its
    arrays (render/bakes.py read_geometry_entry, scene/bvh.py check_trees): said in one warning
    naming it, built again, and the frame is the fresh cache's."""
    from iblbake.render import render
    from iblbake.scene import load as scene_load
    from tests.helpers import mend_cache_entry, scene_file, write_exr
    import trimesh
    trimesh.creation.icosphere(subdivisions=3).export(tmp_path / "ball.ply")
    env = write_exr(tmp_path / "sky.exr", np.full((8, 16, 3), 0.5, np.float32))
    p = scene_file(tmp_path, env, materials={"m": {"roughness": 0.5}},
                   objects=[{"mesh": {"path": str(tmp_path / "ball.ply")}, "material": "m"}],
                   camera={"perspective": {"position": [0, 0, 4], "look_at": [0, 0, 0], "fov_y": 40},
                           "resolution": [16, 16]},
                   effects={"diffuse": "reference", "specular": "reference",
                            "reference": {"max_samples": 4, "target_noise": 0}})
    want = render(scene_load.load(p), cache_root=tmp_path / "cache")
    entry = next(e for e in (tmp_path / "cache").iterdir() if e.name.startswith("geometry-"))
    if mend == "child past the nodes":
        nodes = np.load(entry / "bvh.npy")
        nodes.view(np.int32)[0, 3] = len(nodes)              # the root's children past the end
        mend_cache_entry(entry, bvh=nodes)
    elif mend == "leaf past the triangles":
        nodes = np.load(entry / "bvh.npy")
        leaf = np.flatnonzero(nodes.view(np.int32)[:, 7] > 0)[0]
        nodes.view(np.int32)[leaf, 3] = 10 ** 6
        mend_cache_entry(entry, bvh=nodes)
    elif mend == "wide leaf record":
        wide = np.load(entry / "bvh4.npy")
        mend_cache_entry(entry, bvh4=wide[:-3])               # a leaf's record cut short
    elif mend == "closed of another mesh":
        mend_cache_entry(entry, closed=np.load(entry / "closed.npy")[:-1])
    else:
        mend_cache_entry(entry, lambda m: m["report"].pop("bvh4_nodes"))
    said = []
    got = render(scene_load.load(p), cache_root=tmp_path / "cache", warn=said.append)
    again = [w for w in said if "baking it again" in w]
    assert len(again) == 1 and entry.name in again[0], said
    assert np.array_equal(got.hdr, want.hdr)


def small_trees():
    """(nodes, wide records, triangles, wide nodes) of random triangle soups of 1 to 1000 triangles
    (a root that is a leaf, one level, several)."""
    for n in (1, 2, 5, 17, 1000):
        v = np.random.default_rng(n).random((n, 3, 3)).astype(np.float32)
        b = build_bvh(v.min(1), v.max(1))
        o = b.order
        yield b.nodes.copy(), device_tree(b, v[o, 0], v[o, 1], v[o, 2]), n, len(b.wide)


DAMAGES = {"binary loop": "binary BVH node's child numbered before it",
           "binary child past the end": "binary BVH node's child numbered before it or past the nodes",
           "binary leaf past the triangles": "binary BVH leaf's triangles out of range",
           "wide loop": "wide BVH node's child numbered before it",
           "wide leaf record misaligned": "wide BVH leaf code off its records",
           "wide leaf past the triangles": "wide BVH leaf's triangles out of range",
           "open box on an empty lane": "empty wide BVH lane with a box a ray could meet",
           "deeper than the stack": "wide BVH deeper than the traversal's stack"}


@pytest.mark.parametrize("damage", ["none", *DAMAGES])
def test_check_trees_refuses_what_would_read_outside_or_loop(damage, monkeypatch):
    """scene/bvh.py check_trees passes every tree the builders make and refuses each damage a
    traversal would follow outside its arrays or round forever (one damage at a time)."""
    from iblbake.scene.bvh import check_trees
    for nodes, wide, n, wn in list(small_trees()):     # built before the stack is shrunk
        if n < 17 and damage != "none":
            continue                                   # the damages below need inner nodes
        ints, rows = nodes.view(np.int32), wn * FLOAT4S["BVH4_NODE"]
        codes = wide[:rows].reshape(wn, FLOAT4S["BVH4_NODE"], 4).view(np.int32)[:, 6]
        inner = np.flatnonzero(ints[:, 7] == 0)
        leaf_lane = np.argwhere(codes < -1)[0]
        if damage == "binary loop":
            ints[inner[-1], 3] = inner[-1] - 1          # a child numbered before its parent
        elif damage == "binary child past the end":
            ints[inner[0], 3] = len(nodes) - 1
        elif damage == "binary leaf past the triangles":
            ints[np.flatnonzero(ints[:, 7] > 0)[-1], 3] = n
        elif damage == "wide loop":
            codes[1, np.argmax(codes[1] >= 0) if (codes[1] >= 0).any() else 0] = 1
        elif damage == "wide leaf record misaligned":
            codes[tuple(leaf_lane)] -= 1
        elif damage == "wide leaf past the triangles":
            wide[rows:].reshape(-1, FLOAT4S["BVH4_LEAF"], 4).view(np.int32)[-1, 9, 0] = n
        elif damage == "open box on an empty lane":
            empty = np.argwhere(codes == -1)[0]
            lanes = wide[:rows].reshape(wn, FLOAT4S["BVH4_NODE"], 4)
            lanes[empty[0], 0:3, empty[1]], lanes[empty[0], 3:6, empty[1]] = -1e9, 1e9
        elif damage == "deeper than the stack":
            monkeypatch.setattr(bvh_module, "BVH_STACK", 3 * 1 + 1)   # one level fits, two do not
        if damage == "none":
            check_trees(nodes, wide, n, wn)
        else:
            with pytest.raises(ValueError, match=DAMAGES[damage]):
                check_trees(nodes, wide, n, wn)
