"""Write the meshes of the real-time GI corpus (examples/corpus/*.yaml) into examples/corpus/meshes/
(made by `make meshes`, not committed): OBJ quads wound out of a box and into it, the walls of two
rooms split by a wall of no thickness, a room whose one wall has a window, a watertight cube (a
solid), a large block the probes' grid cuts through, a textured glTF with a double-sided leaf,
a single-sided box and a chequered floor, and ordinary interiors of quads of no thickness (a
corridor open at one end, two storeys split by a slab, a room wound either way lit through a
window, an L-shaped room, a room under a skylight). Each a few triangles: what breaks GI is their sides, not
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

# Ordinary interiors (issue 59), every wall a quad of no thickness (double-sided as every surface is)
def panel(o, u, v, a0, a1, b0, b1):
    """The quad o + a u + b v over [a0, a1] x [b0, b1], counter-clockwise seen from u x v."""
    o, u, v = np.asarray(o, float), np.asarray(u, float), np.asarray(v, float)
    return [tuple(o + a * u + b * v) for a, b in ((a0, b0), (a1, b0), (a1, b1), (a0, b1))]


def holed(o, u, v, a, b, hole):
    """The wall panel(o, u, v, 0, a, 0, b) less the window hole = (a0, a1, b0, b1): four quads."""
    a0, a1, b0, b1 = hole
    return [panel(o, u, v, 0, a, 0, b0), panel(o, u, v, 0, a, b1, b),
            panel(o, u, v, 0, a0, b0, b1), panel(o, u, v, a1, a, b0, b1)]


X, Y, Z = np.eye(3)
# a corridor 1.2 wide, 1.6 high and 8 long (z from 0 to -8), open at z = 0, wound inwards
for half, z0 in (("near", 0), ("far", -4)):      # its floor, ceiling and side walls in two halves
    obj(f"corridor_{half}.obj", [panel((-0.6, 0, z0), X, -Z, 0, 1.2, 0, 4),
                                 panel((-0.6, 1.6, z0), -Z, X, 0, 4, 0, 1.2),
                                 panel((-0.6, 0, z0), -Z, Y, 0, 4, 0, 1.6),
                                 panel((0.6, 0, z0 - 4), Z, Y, 0, 4, 0, 1.6)])
obj("corridor_end.obj", [panel((-0.6, 0, -8), X, Y, 0, 1.2, 0, 1.6)])

# two storeys of 4 x 2 x 4 (x, z in [-2, 2]) split at y = 2 by one quad; the lower one closed but
# for a window in its back wall (z = -2), the upper one open on its +x side, roofed
obj("storey_lower.obj", [panel((-2, 0, 2), X, -Z, 0, 4, 0, 4),                              # floor
                         panel((-2, 0, 2), -Z, Y, 0, 4, 0, 2), panel((2, 0, -2), Z, Y, 0, 4, 0, 2),
                         panel((2, 0, 2), -X, Y, 0, 4, 0, 2)]
    + holed((-2, 0, -2), X, Y, 4, 2, (1.6, 2.4, 0.8, 1.4)))
obj("storey_slab.obj", [panel((-2, 2, 2), X, -Z, 0, 4, 0, 4)])
obj("storey_upper.obj", [panel((-2, 2, 2), -Z, Y, 0, 4, 0, 2), panel((-2, 2, -2), X, Y, 0, 4, 0, 2),
                         panel((2, 2, 2), -X, Y, 0, 4, 0, 2), panel((-2, 4, -2), X, Z, 0, 4, 0, 4)])

# a room of 4 x 3 x 4 (x, z in [-2, 2]) closed but for a window in its +x wall, its walls wound
# either way (in: floor, left, front; out: ceiling, back, the window wall's pieces alternating)
obj("quad_floor.obj", [panel((-2, 0, 2), X, -Z, 0, 4, 0, 4)])
obj("quad_ceiling.obj", [panel((-2, 3, 2), X, -Z, 0, 4, 0, 4)])
obj("quad_left.obj", [panel((-2, 0, 2), -Z, Y, 0, 4, 0, 3)])
obj("quad_back.obj", [flipped(panel((-2, 0, -2), X, Y, 0, 4, 0, 3))])
obj("quad_front.obj", [panel((2, 0, 2), -X, Y, 0, 4, 0, 3)])
obj("quad_window.obj", [q if i % 2 else flipped(q)
                        for i, q in enumerate(holed((2, 0, -2), Z, Y, 4, 3, (1.3, 2.7, 1.0, 2.2)))])

# an L-shaped room 2.4 high: a leg along x ([0, 4] x [0, 1.6]) and one along z ([0, 1.6] x [0, 4]),
# wound inwards, a window at the end of the x leg (x = 4)
L = [(0, 0), (4, 0), (4, 1.6), (1.6, 1.6), (1.6, 4), (0, 4)]
lwalls = []
for (x0, z0), (x1, z1) in zip(L, L[1:] + L[:1]):
    d = np.array([x1 - x0, 0, z1 - z0], float)
    n = float(np.linalg.norm(d))
    if (x0, z0) == (4, 0):                   # the window wall (the outline runs so that d x Y faces in)
        lwalls += holed((x0, 0, z0), d / n, Y, n, 2.4, (0.4, 1.2, 0.9, 1.8))
    else:
        lwalls.append(panel((x0, 0, z0), d / n, Y, 0, n, 0, 2.4))
obj("l_walls.obj", lwalls)
obj("l_floor.obj", [panel((0, 0, 1.6), X, -Z, 0, 4, 0, 1.6), panel((0, 0, 4), X, -Z, 0, 1.6, 0, 2.4)])
obj("l_ceiling.obj", [panel((0, 2.4, 0), X, Z, 0, 4, 0, 1.6), panel((0, 2.4, 1.6), X, Z, 0, 1.6, 0, 2.4)])

# a room of 3 x 2.4 x 5 (x in [-1.5, 1.5], z in [-2.5, 2.5]) wound outwards, lit by a skylight
obj("skylight_room.obj", [flipped(panel((-1.5, 0, 2.5), X, -Z, 0, 3, 0, 5)),
                          flipped(panel((-1.5, 0, 2.5), -Z, Y, 0, 5, 0, 2.4)),
                          flipped(panel((1.5, 0, -2.5), Z, Y, 0, 5, 0, 2.4)),
                          flipped(panel((-1.5, 0, -2.5), X, Y, 0, 3, 0, 2.4)),
                          flipped(panel((1.5, 0, 2.5), -X, Y, 0, 3, 0, 2.4))]
    + [flipped(q) for q in holed((-1.5, 2.4, -2.5), X, Z, 3, 5, (1.0, 2.0, 1.7, 3.3))])

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
