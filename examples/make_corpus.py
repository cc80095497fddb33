"""Write the meshes of the real-time GI corpus (examples/corpus/*.yaml) into examples/corpus/meshes/
(made by `make meshes`, not committed): OBJ quads wound out of a box and into it, the walls of two
rooms split by a wall of no thickness, a room whose one wall has a window, a watertight cube (a
solid), a large block the probes' grid cuts through, and a textured glTF with a double-sided leaf,
a single-sided box and a chequered floor. Each a few triangles: what breaks GI is their sides, not
their size."""

import sys
from pathlib import Path

import numpy as np

root = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent / "corpus"
out = root / "meshes"
out.mkdir(parents=True, exist_ok=True)


def obj(name: str, quads) -> None:
    """An OBJ of quads, each four corners in the order that makes its winding (counter-clockwise
    seen from its front), split into two triangles."""
    lines, k = [], 1
    for q in quads:
        lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in q]
        lines += [f"f {k} {k + 1} {k + 2}", f"f {k} {k + 2} {k + 3}"]
        k += 4
    (out / name).write_text("\n".join(lines) + "\n")


def flipped(q):
    return q[::-1]


# the open box: floor y = 0, back z = -1, left x = -1, right x = 1; as listed each faces out
floor = [(-1, 0, -1), (1, 0, -1), (1, 0, 1), (-1, 0, 1)]
back = [(-1, 0, -1), (-1, 2, -1), (1, 2, -1), (1, 0, -1)]
left = [(-1, 0, -1), (-1, 0, 1), (-1, 2, 1), (-1, 2, -1)]
right = [(1, 0, -1), (1, 2, -1), (1, 2, 1), (1, 0, 1)]
for name, q in (("floor", floor), ("back", back), ("left", left), ("right", right)):
    obj(f"box_{name}_out.obj", [q])
    obj(f"box_{name}_in.obj", [flipped(q)])

# two rooms of 2 x 2 x 2 split at x = 0 by a wall of no thickness: the left one roofless, the right
# one roofed, lit only under a lintel (its front wall open below y = 0.6)
def rect(c, u, v):
    c, u, v = np.asarray(c, float), np.asarray(u, float), np.asarray(v, float)
    return [tuple(c - u - v), tuple(c + u - v), tuple(c + u + v), tuple(c - u + v)]


obj("rooms_shell.obj", [rect((-1, 0, 0), (1, 0, 0), (0, 0, -1)), rect((1, 0, 0), (1, 0, 0), (0, 0, -1)),   # floors
                        rect((1, 2, 0), (1, 0, 0), (0, 0, 1)),                                         # the roof
                        rect((-2, 1, 0), (0, 0, 1), (0, 1, 0)), rect((2, 1, 0), (0, 0, -1), (0, 1, 0)),    # end walls
                        rect((-1, 1, -1), (-1, 0, 0), (0, 1, 0)), rect((1, 1, -1), (-1, 0, 0), (0, 1, 0)),  # backs
                        rect((1, 1.3, 1), (1, 0, 0), (0, 0.7, 0))])                                    # lintel
obj("rooms_wall.obj", [rect((0, 1, 0), (0, 0, 1), (0, 1, 0))])

# a closed room of 4 x 3 x 4 wound inwards, its wall z = -2 with a window (x in [-0.6, 0.6], y in
# [1, 2]): not watertight, so no solid
room = [rect((0, 0, 0), (2, 0, 0), (0, 0, -2)), rect((0, 3, 0), (2, 0, 0), (0, 0, 2)),
        rect((-2, 1.5, 0), (0, 0, -2), (0, 1.5, 0)), rect((2, 1.5, 0), (0, 0, 2), (0, 1.5, 0)),
        rect((0, 1.5, 2), (-2, 0, 0), (0, 1.5, 0))]
wz = -2.0
window_wall = [[(-2, 0, wz), (2, 0, wz), (2, 1, wz), (-2, 1, wz)], [(-2, 2, wz), (2, 2, wz), (2, 3, wz), (-2, 3, wz)],
               [(-2, 1, wz), (-0.6, 1, wz), (-0.6, 2, wz), (-2, 2, wz)], [(0.6, 1, wz), (2, 1, wz), (2, 2, wz), (0.6, 2, wz)]]
obj("window_room.obj", room + window_wall)


def cube(c, h):
    """A watertight cube of half sizes h about c, wound outwards, corners shared exactly."""
    c, h = np.asarray(c, float), np.asarray(h, float)
    p = [tuple(c + h * s) for s in np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                                             [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]])]
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (3, 7, 6, 2), (0, 4, 7, 3), (1, 2, 6, 5)]
    return p, faces


def obj_shared(name: str, points, faces) -> None:
    """An OBJ whose quads share their corners (a closed mesh)."""
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in points]
    for a, b, c, d in faces:
        lines += [f"f {a + 1} {b + 1} {c + 1}", f"f {a + 1} {c + 1} {d + 1}"]
    (out / name).write_text("\n".join(lines) + "\n")


obj_shared("cube.obj", *cube((0, 0.35, 0), (0.35, 0.35, 0.35)))
obj_shared("block.obj", *cube((0.6, 0.5, 0), (0.9, 0.5, 0.9)))
obj("plate.obj", [rect((0, 0, 0), (3, 0, 0), (0, 0, -3))])

# a textured glTF: a chequered floor, a double-sided leaf (one quad, no thickness), a single-sided box
import trimesh                                   # noqa: E402 (only for the glTF)
from PIL import Image                            # noqa: E402
from trimesh.visual.material import PBRMaterial  # noqa: E402

n = 64
cy, cx = np.indices((n, n)) // 8
check = np.where((cx + cy) % 2 == 0, 200, 60).astype(np.uint8)
tex = Image.fromarray(np.stack([check, (check * 0.9).astype(np.uint8), (check * 0.7).astype(np.uint8)], -1))


def textured(vertices, faces, uv, name, double_sided, color):
    mat = PBRMaterial(name=name, baseColorTexture=tex, baseColorFactor=color, metallicFactor=0.0, roughnessFactor=0.8,
                      doubleSided=double_sided)
    m = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    m.visual = trimesh.visual.TextureVisuals(uv=uv, material=mat)
    return m


quad_f = np.array([[0, 1, 2], [0, 2, 3]])
floor_v = np.array([[-2, 0, 2], [2, 0, 2], [2, 0, -2], [-2, 0, -2]], float)
leaf_v = np.array([[-0.9, 0.1, -0.4], [-0.1, 0.1, -0.9], [-0.1, 1.2, -0.9], [-0.9, 1.2, -0.4]], float)
uvq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
pts, fq = cube((0.7, 0.3, 0.2), (0.3, 0.3, 0.3))
box_v = np.array(pts)
box_f = np.array([t for a, b, c, d in fq for t in ((a, b, c), (a, c, d))])
scene = trimesh.Scene()
scene.add_geometry(textured(floor_v * 1, quad_f, uvq * 4, "floor", False, [255, 255, 255, 255]), geom_name="floor")
scene.add_geometry(textured(leaf_v, quad_f, uvq, "leaf", True, [120, 255, 120, 255]), geom_name="leaf")
scene.add_geometry(textured(box_v, box_f, box_v[:, [0, 2]] + 0.5, "box", False, [255, 160, 120, 255]), geom_name="box")
(out / "garden.glb").write_bytes(scene.export(file_type="glb"))
print(f"wrote the corpus meshes into {out}")
