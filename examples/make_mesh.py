"""Write examples/meshes/knot.ply: a (3, 2) torus-knot tube of 400 x 128 x 2 = 102,400 triangles
with smooth vertex normals, for the mesh scene and the render benchmark (generated, not committed)."""

import sys
from pathlib import Path

import numpy as np
import trimesh

out = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent / "meshes" / "knot.ply")
nu, nv, p, q, tube = 400, 128, 3, 2, 0.16
t = np.linspace(0, 2 * np.pi, nu, endpoint=False)
centre = np.stack([(2 + np.cos(q * t)) * np.cos(p * t), np.sin(q * t), (2 + np.cos(q * t)) * np.sin(p * t)], 1) * 0.35
tangent = np.gradient(centre, axis=0)
tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
normal = np.cross(tangent, [0, 1, 0])
normal /= np.linalg.norm(normal, axis=1, keepdims=True)
binormal = np.cross(tangent, normal)
a = np.linspace(0, 2 * np.pi, nv, endpoint=False)
ring = np.cos(a)[None, :, None] * normal[:, None] + np.sin(a)[None, :, None] * binormal[:, None]
verts = (centre[:, None] + tube * ring).reshape(-1, 3)
i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
i1, j1 = (i + 1) % nu, (j + 1) % nv
v00, v10, v01, v11 = i * nv + j, i1 * nv + j, i * nv + j1, i1 * nv + j1
faces = np.concatenate([np.stack([v00, v01, v10], -1).reshape(-1, 3), np.stack([v10, v01, v11], -1).reshape(-1, 3)])
mesh = trimesh.Trimesh(verts, faces, vertex_normals=ring.reshape(-1, 3), process=False)
out.parent.mkdir(parents=True, exist_ok=True)
mesh.export(out)
print(f"{out}: {len(faces)} triangles")
