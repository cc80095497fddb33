"""Scene files for `iblbake render`: YAML in, a validated, defaults-filled Scene out.

load() reads the file (yaml_lines: safe YAML with the line of every key), applies `--set
key.path=value` overrides (parsed as YAML values) and a sweep cell's values, validates against
the schema (iblbake.scene.schema, the single description of every key), then resolves what
refers to what: the camera, materials, files and outputs. Errors are one line naming the file,
the line and the dotted key, with the closest valid key for a typo.
"""

from __future__ import annotations

import difflib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

from iblbake.errors import InputError, UsageError
from iblbake.scene.schema import LIGHTMAP_LOBED, SCHEMA, ListOf, MapOf, Section, _Bad
from iblbake.io import confine, reads
from iblbake.scene.yaml_lines import MAX_SCENE_BYTES, load_with_lines

FRAME_SUFFIXES = (".png", ".exr")
AOVS = ("normal", "albedo", "depth", "object")


@dataclass
class Scene:
    """A validated scene: data holds every key of docs/scene.md (defaults filled, paths
    absolute); source is the scene file (or what a mapping was called), folder where its
    relative paths resolve, lines the line of each dotted key, writes (what names it, path) of
    every output; raw what was validated (the file's or mapping's data, its overrides and values
    applied) and overridden where each overridden key came from: load_any validates it again."""

    data: dict                     # validated, defaults filled, paths absolute
    source: str                    # the scene file
    folder: Path
    lines: dict = field(default_factory=dict)
    writes: list = field(default_factory=list)     # (what names it, path) of every output
    raw: dict | None = field(default=None, repr=False, compare=False)
    overridden: dict = field(default_factory=dict, repr=False, compare=False)
    # a copy of data as validated: data is read-only, and edited_key finds an edit made since
    validated: dict | None = field(default=None, repr=False, compare=False)

    def __getitem__(self, k):
        return self.data[k]


class _Validator:
    def __init__(self, source: str, lines: dict, overridden: dict):
        self.source, self.lines, self.overridden = source, lines, overridden

    def where(self, path: str) -> str:
        p = path
        while p:                  # a key set by --set (or a sweep), or inside one: not the file's line
            if p in self.overridden:
                return f"{self.source}: {self.overridden[p]}"
            p = p.rpartition(".")[0]
        p = path
        while p and p not in self.lines:
            p = p.rpartition(".")[0]
        line = self.lines.get(p)
        return f"{self.source}:{line}" if line else self.source

    def fail(self, path: str, msg: str, at: str | None = None):
        """`path: msg`, said where `at` (default path) came from: its line, or the flag that set it."""
        raise InputError(f"{self.where(at or path)}: {path or 'scene'}: {msg}")

    def section(self, spec: Section, value, path: str) -> dict:
        if value is None:
            value = {}
        if not isinstance(value, dict):
            self.fail(path, f"expected a mapping of keys ({', '.join(spec.fields)}), got {value!r}")
        out = {}
        for k in value:
            if k not in spec.fields:
                sub = f"{path}.{k}" if path else str(k)
                near = difflib.get_close_matches(str(k), list(spec.fields), 1, 0.6)
                hint = f"did you mean {near[0]!r}?" if near else f"valid keys: {', '.join(spec.fields)}"
                self.fail(sub, f"unknown key ({hint})")
        for k in spec.required:
            if k not in value or value[k] is None:
                self.fail(path, f"missing required key {k!r}")
        if spec.exclusive:
            given = [k for k in spec.exclusive if k in value]
            if len(given) != 1 and not (not given and path == "camera"):
                what = "one of " + " | ".join(spec.exclusive)
                self.fail(path, f"give exactly {what} (got {', '.join(given) or 'none'})")
        for k, f in spec.fields.items():
            sub = f"{path}.{k}" if path else k
            if isinstance(f, Section):
                if spec.exclusive and k in spec.exclusive and k not in value:
                    continue
                if f.optional and value.get(k) is None:
                    out[k] = None
                    continue
                out[k] = self.section(f, value.get(k), sub)
            elif isinstance(f, MapOf):
                m = value.get(k) or {}
                if not isinstance(m, dict):
                    self.fail(sub, f"expected a mapping of names to {f.section.doc}s")
                for name in m:
                    if not isinstance(name, str):
                        self.fail(f"{sub}.{name}", f"a name is a string, not {type(name).__name__} (quote it)")
                out[k] = {name: self.section(f.section, v, f"{sub}.{name}") for name, v in m.items()}
            elif isinstance(f, ListOf):
                seq = value.get(k) or []
                if not isinstance(seq, list):
                    self.fail(sub, "expected a list")
                out[k] = [self.section(f.section, v, f"{sub}.{i}") for i, v in enumerate(seq)]
            else:
                v = value.get(k)
                if v is None:
                    out[k] = f.default
                else:
                    try:
                        out[k] = f.check(v)
                    except _Bad as e:
                        self.fail(sub, str(e))
        return out


def _apply_override(data: dict, assignment: str, name: str = "--set") -> tuple:
    """Apply one KEY.PATH=VALUE; `name` is what errors call the overrides (a flag, an argument).
    (key, the sections it made)."""
    if not isinstance(assignment, str):
        raise UsageError(f"{name} {assignment!r}: expected a 'KEY.PATH=VALUE' string, e.g. effects.samples=40")
    key, sep, raw = assignment.partition("=")
    key = key.strip()
    if not sep or not key:
        raise UsageError(f"{name} {assignment!r}: expected KEY.PATH=VALUE, e.g. effects.samples=40")
    if not raw.strip():
        raise UsageError(f"{name} {assignment!r}: no value after '='; give one (null takes the default)")
    try:
        value = load_with_lines(raw, f"{name} {key}")[0]
    except InputError as e:              # a value that does not parse is a usage error (exit 2)
        raise UsageError(str(e)) from None
    return key, set_path(data, key, value, f"{name} {key}")


def set_path(data: dict, key: str, value, origin: str) -> list:
    """data[key.path] = value, creating sections on the way; `origin` names where the assignment
    came from in errors (a --set flag, a sweep axis). The key paths of the sections it made (an
    error in one, a misspelt name say, is the assignment's, not the file's)."""
    parts = key.split(".")
    node, made = data, []
    for i, p in enumerate(parts[:-1]):
        if isinstance(node, list):
            if not p.isdigit() or int(p) >= len(node):
                raise InputError(f"{origin}: {'.'.join(parts[:i + 1])}: no item {p} in a list of {len(node)}")
            node = node[int(p)]
        elif isinstance(node, dict):
            if node.get(p) is None:
                node[p] = {}
                made.append(".".join(parts[:i + 1]))
            node = node[p]
        else:
            raise InputError(f"{origin}: {'.'.join(parts[:i])} is a value, not a section")
    last = parts[-1]
    if isinstance(node, list):
        if not last.isdigit() or int(last) >= len(node):
            raise InputError(f"{origin}: no item {last} in a list of {len(node)}")
        node[int(last)] = value
    elif isinstance(node, dict):
        node[last] = value
    else:
        raise InputError(f"{origin}: {'.'.join(parts[:-1])} is a value, not a section")
    return made


def _resolve_inside(folder: Path, rel: str, what: str, where: str) -> Path:
    """Scene output paths stay inside the scene's folder (io/confine.py): `../../x`, `/etc/x` and
    a link out are refused."""
    full, why = confine.output_path(folder, rel)
    if full is None:
        raise InputError(f"{where}: {what}: {rel!r} {why}; write outputs inside it, pass -o on the "
                         f"command line, or {confine.HINT}")
    return full


def _must_be_file(v, key: str, path: str, what: str, folder: Path, limit: int, hint: str = "") -> None:
    """A regular file within its kind's size limit (checked before anything opens it: a device
    or a FIFO would be read forever or block)."""
    if os.path.isdir(path):          # not Path.is_dir: a name too long raised OSError
        v.fail(key, f"{path} is a folder; give the path of {what} file")
    if not os.path.exists(path):
        v.fail(key, f"{path} not found; give the path of {what} (relative to {folder})")
    try:
        reads.check_file(path, limit, what, hint)
    except InputError as e:
        v.fail(key, str(e))


def load(path, overrides=(), outputs=None, values=(), origin: str = "--set", override_name: str = "--set") -> Scene:
    """Read, override, validate. `overrides` are KEY.PATH=VALUE strings (--set; errors call them
    `override_name`), `values` typed (key path, value) pairs applied after them (a sweep cell's),
    `origin` what errors call the place the latter came from. `outputs` (from -o) replace
    output.frame."""
    path = Path(path)
    data, lines = _read(path)
    return _validated(data, lines, str(path), path.resolve().parent, overrides, outputs, values, origin,
                      override_name)


def load_data(data: dict, folder=".", overrides=(), outputs=None, values=(), origin: str = "--set",
              source: str = "<scene>", override_name: str = "--set") -> Scene:
    """load() of a scene given as a mapping (what a scene file's YAML holds) instead of a file:
    relative paths resolve in `folder`, errors name `source` (no line numbers). A mapping made in
    Python may hold numpy scalars and arrays, tuples and path objects: they are read as the
    numbers, lists and strings a scene file would hold (plain_values)."""
    from collections.abc import Mapping
    if not isinstance(data, Mapping):
        raise InputError(f"{source}: a scene is a mapping of sections (camera, environment, "
                         f"materials, objects, effects, output), not {type(data).__name__}")
    return _validated(plain_values(data, source), {}, source, Path(folder).resolve(), overrides, outputs, values,
                      origin, override_name)


def load_any(scene, overrides=(), outputs=None, values=(), origin: str = "--set",
             override_name: str = "--set") -> Scene:
    """load() of a scene file, or a Scene validated again from what it was validated from (its
    raw data and lines) with more overrides, outputs and values (a study's rungs of a scene given
    as a mapping or a Scene)."""
    if not isinstance(scene, Scene):
        return load(scene, overrides, outputs, values, origin, override_name)
    if scene.raw is None:
        raise InputError(f"{scene.source}: this Scene was not made by the scene loader (it has no data to "
                         f"validate again); load it with iblbake.load_scene (a file or a mapping)")
    import copy
    return _validated(copy.deepcopy(scene.raw), scene.lines, scene.source, scene.folder, overrides, outputs, values,
                      origin, override_name, dict(scene.overridden))


MAX_DEPTH = 64      # sections, lists and values nest a few levels deep in any scene


def plain_values(value, source: str = "<scene>", path: str = "", within: tuple = ()):
    """A copy of a mapping made in Python with what a scene file holds in place of its Python
    and numpy kinds: numpy scalars as numbers (a numpy bool a bool, refused where a number is
    expected, as True is), numpy arrays and tuples as lists, path objects as strings. What no
    scene file holds is an InputError naming `source` and the key: a key that is not a string,
    a generator or another object, a mapping or list that contains itself."""
    from collections.abc import Mapping

    def fail(msg):
        raise InputError(f"{source}: {path or 'scene'}: {msg}")

    if any(value is v for v in within):
        fail("contains itself (a mapping or list inside itself); give each section once")
    if len(within) > MAX_DEPTH:
        fail(f"nested deeper than {MAX_DEPTH} levels; a scene's sections are a few levels deep")
    if isinstance(value, Mapping):
        for k in value:
            if not isinstance(k, str):
                fail(f"key {k!r} is not a string (keys and names are strings)")
        return {k: plain_values(v, source, f"{path}.{k}".lstrip("."), within + (value,)) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_values(v, source, f"{path}.{i}".lstrip("."), within + (value,)) for i, v in enumerate(value)]
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if type(value).__module__ == "numpy" and hasattr(value, "tolist"):     # numpy is not imported for it
        return plain_values(value.tolist(), source, path, within)
    if value is None or isinstance(value, (str, int, float)):
        return value
    fail(f"{type(value).__name__} is not a value a scene holds; give a mapping, a list, a string or a number")


def _validated(data, lines, source, folder, overrides, outputs, values, origin, override_name="--set",
               overridden=None) -> Scene:
    import copy
    confine.allowed()             # a bad IBLBAKE_ALLOW_OUTSIDE is refused on every load, not when a path meets the rule
    overridden = overridden or {}
    for a in overrides:
        key, made = _apply_override(data, a, override_name)
        overridden.update({**dict.fromkeys(made, override_name), key: override_name})
    for key, value in values:
        made = set_path(data, key, value, origin)
        overridden.update({**dict.fromkeys(made, origin), key: origin})
    raw = copy.deepcopy(data)
    v = _Validator(source, lines, overridden)
    out = v.section(SCHEMA, data, "")
    _resolve_camera(v, out["camera"])
    _resolve_references(v, out, folder)
    _resolve_names(v, out)
    _resolve_reflection_probes(v, out["reflection_probes"])
    _resolve_probes(v, out["probes"])
    _resolve_basis_specular(v, out["effects"], out["probes"])
    _resolve_lightmap_specular(v, out, raw)
    _resolve_lightmap(v, out, raw)
    _resolve_specular_fits(out, raw)
    _resolve_sun(out, raw)
    writes = _resolve_outputs(v, out["output"], folder, outputs)
    return Scene(out, source, folder, lines, writes, raw, overridden, copy.deepcopy(out))


def edited_key(scene: Scene) -> str | None:
    """The first dotted key of scene.data that differs from what was validated (an edit made to
    the read-only data since), '' for the whole mapping, or None where it is as validated (or the
    Scene was not made by the loader)."""
    def first(a, b, path):
        if type(a) is not type(b):
            return path
        if isinstance(a, dict):
            for k in list(a) + [k for k in b if k not in a]:
                if k not in a or k not in b:
                    return f"{path}.{k}".lstrip(".")
                found = first(a[k], b[k], f"{path}.{k}")
                if found is not None:
                    return found.lstrip(".")
            return None
        if isinstance(a, list):
            if len(a) != len(b):
                return path
            return next((f for f in (first(x, y, f"{path}.{i}") for i, (x, y) in enumerate(zip(a, b)))
                         if f is not None), None)
        return None if a == b else path
    if scene.validated is None:
        return None
    try:
        found = first(scene.data, scene.validated, "")
    except RecursionError:                  # data made to contain itself
        found = ""
    return None if found is None else found.lstrip(".")


def _read(path: Path):
    """The scene file's YAML as a mapping, and the line of every dotted key."""
    source = str(path)
    if not os.path.lexists(path):
        raise InputError(f"{source}: scene file not found")
    try:
        text = reads.read_text(path, MAX_SCENE_BYTES, "a scene file", " (meshes and panoramas go in their own files)")
    except UnicodeDecodeError:
        raise InputError(f"{source}: not a UTF-8 text file; scene files are YAML") from None
    data, lines = load_with_lines(text, source)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise InputError(f"{source}:1: a scene is a mapping of sections (camera, environment, "
                         f"materials, objects, effects, output), not {type(data).__name__}")
    return data, lines


def _resolve_camera(v: "_Validator", cam: dict) -> None:
    """Perspective by default; a view direction and an up vector that define a frame."""
    if "perspective" not in cam and "orthographic" not in cam:
        cam["perspective"] = v.section(SCHEMA.fields["camera"].fields["perspective"],
                                       {"position": [0.0, 0.0, 5.0]}, "camera.perspective")
    proj = "perspective" if "perspective" in cam else "orthographic"
    c = cam[proj]
    fwd = [a - b for a, b in zip(c["look_at"], c["position"])]
    if all(abs(x) < 1e-12 for x in fwd):
        v.fail(f"camera.{proj}.look_at", "equals the camera position; the view direction is undefined")
    cross = [fwd[1] * c["up"][2] - fwd[2] * c["up"][1], fwd[2] * c["up"][0] - fwd[0] * c["up"][2],
             fwd[0] * c["up"][1] - fwd[1] * c["up"][0]]
    if math.sqrt(sum(x * x for x in cross)) <= 1e-9 * math.sqrt(sum(x * x for x in fwd)) * math.sqrt(sum(x * x for x in c["up"])):
        v.fail(f"camera.{proj}.up", "is parallel to the view direction; give another up vector")
    cam["projection"] = proj


def _resolve_references(v: "_Validator", out: dict, folder: Path) -> None:
    """Objects name materials that exist; meshes, maps and the panorama are files (absolute)."""
    for i, o in enumerate(out["objects"]):
        if "mesh" in o:
            given = os.path.normpath(folder / o["mesh"]["path"])      # a link named as given
            o["mesh"]["path"] = str(Path(given).resolve())
            _check_mesh_files(v, f"objects.{i}.mesh.path", given)
        if o["material"] is None:
            if "mesh" in o and Path(o["mesh"]["path"]).suffix.lower() in (".gltf", ".glb"):
                continue                          # shaded with the file's own materials
            v.fail(f"objects.{i}", "missing required key 'material' (only a glTF/GLB mesh brings its own)")
        if o["material"] not in out["materials"]:
            near = difflib.get_close_matches(o["material"], list(out["materials"]), 1, 0.6)
            hint = f"did you mean {near[0]!r}?" if near else \
                f"defined: {', '.join(out['materials']) or 'none'}"
            v.fail(f"objects.{i}.material", f"no material named {o['material']!r} ({hint})")
    from iblbake.io.images import max_pixels_default
    from iblbake.scene.textures import RAISE_TEXTURE_LIMIT, max_texture_pixels

    for name, m in out["materials"].items():
        for key in [k for k in m if k.endswith("_map") and m[k]]:
            given = os.path.normpath(folder / m[key]["path"])
            m[key]["path"] = str(Path(given).resolve())
            _must_be_file(v, f"materials.{name}.{key}.path", given, "an image", folder,
                          reads.image_bytes(max_texture_pixels()), f" ({RAISE_TEXTURE_LIMIT})")
    for i, lt in enumerate(out["lights"]):
        if "spot" in lt and lt["spot"]["inner_cone_angle"] > lt["spot"]["outer_cone_angle"]:
            v.fail(f"lights.{i}.spot.inner_cone_angle", f"{lt['spot']['inner_cone_angle']:g} is wider than "
                                                        f"outer_cone_angle {lt['spot']['outer_cone_angle']:g}")
    env = out["environment"]
    env["path"] = str((folder / env["path"]).resolve()) if not Path(env["path"]).is_absolute() else env["path"]
    limit = max_pixels_default()
    _must_be_file(v, "environment.path", env["path"], "an HDR panorama", folder, reads.image_bytes(limit),
                  f" of at most {limit} pixels (IBLBAKE_MAX_PIXELS or --max-pixels raises it)")


def _check_mesh_files(v: "_Validator", key: str, path: str) -> None:
    """A mesh (and the buffers and images a .gltf or .glb names beside it) is a regular file within the
    mesh limit; a missing one said with the line that names it (the loader's words, scene/geometry.py)."""
    from iblbake.scene.gltf import named_files

    if not os.path.exists(path):          # not Path.exists: a name too long raised OSError
        # named as the mesh's, said where its path came from (a path given by --set is said as that)
        v.fail(key.removesuffix(".path"), f"mesh {Path(path).resolve()} not found", at=key)
    try:
        reads.check_file(path, reads.mesh_bytes(), "a mesh", reads.MESH_HINT)
        named = named_files(path)
        for _, f, _ in named:
            if f is not None and os.path.exists(f):
                reads.check_file(f, reads.mesh_bytes(), "a glTF buffer or image", reads.MESH_HINT)
    except InputError as e:
        v.fail(key, str(e))
    for uri, _, why in named:      # one out of the glTF's folder (io/confine.py): nothing has read it
        if why:
            v.fail(key, f"{path}: the URI {uri!r} {why}")


def _resolve_names(v: "_Validator", out: dict) -> None:
    """Object names are unique; each reflection probe's `exclude` names objects (by name or
    objects.N): their indices go into its exclude_ids."""
    given = {}
    for i, o in enumerate(out["objects"]):
        if o["name"] is not None:
            if o["name"] in given:
                v.fail(f"objects.{i}.name", f"{o['name']!r} is the name of objects.{given[o['name']]} too; "
                                            "give each object its own name")
            given[o["name"]] = i
    for k, p in enumerate(out["reflection_probes"]):
        ids = []
        for name in p["exclude"] or []:
            if name in given:
                ids.append(given[name])
            elif name.startswith("objects.") and name[8:].isdigit() and int(name[8:]) < len(out["objects"]):
                ids.append(int(name[8:]))
            else:
                near = difflib.get_close_matches(name, list(given), 1, 0.6)
                hint = f"did you mean {near[0]!r}?" if near else \
                    f"name objects with objects.N.name, or write objects.N ({len(out['objects'])} objects)"
                v.fail(f"reflection_probes.{k}.exclude", f"no object named {name!r} ({hint})")
        p["exclude_ids"] = sorted(set(ids))


def object_label(data: dict, oid: int) -> str:
    """What messages call object oid: its name and index, or its index and what it is."""
    o = data["objects"][oid]
    if o.get("name"):
        return f"{o['name']!r} (objects.{oid})"
    kind = "mesh " + Path(o["mesh"]["path"]).name if "mesh" in o else ("sphere" if "sphere" in o else "plane")
    return f"objects.{oid} ({kind})"


def _resolve_reflection_probes(v: "_Validator", probes: list) -> None:
    """Each probe's influence is whole (a box's corners in order, a sphere's radius) and holds it."""
    for i, p in enumerate(probes):
        where = f"reflection_probes.{i}"
        if p["shape"] == "box":
            for k in ("min", "max"):
                if p[k] is None:
                    v.fail(where, f"missing required key '{k}' (a box influence has min and max corners)")
            if any(lo >= hi for lo, hi in zip(p["min"], p["max"])):
                v.fail(f"{where}.max", f"{p['max']} is not above min {p['min']} on every axis")
            if any(not lo <= x <= hi for lo, x, hi in zip(p["min"], p["position"], p["max"])):
                v.fail(f"{where}.position", f"{p['position']} lies outside the box {p['min']}..{p['max']}; "
                                            "put the probe inside its influence")
            if p["radius"] is not None:
                v.fail(f"{where}.radius", "is a sphere influence's; a box influence is its min and max (shape: "
                                          "sphere takes radius)")
        else:
            if p["radius"] is None:
                v.fail(where, "missing required key 'radius' (a sphere influence about position)")
            for k in ("min", "max"):
                if p[k] is not None:
                    v.fail(f"{where}.{k}", "is a box influence's corner; a sphere influence is its radius about "
                                           "position (shape: box takes min and max)")


def _resolve_basis_specular(v: "_Validator", fx: dict, probes: dict) -> None:
    """A specular basis (core/bases SPECULAR) beside a different diffuse basis, or beside probes that
    store one: the shade pass compiles one basis header a frame (kernels/bases.h); `specular:
    probes` from probes whose basis carries a specular lobe, beside no distant basis."""
    from iblbake.core import bases
    from iblbake.core.bases.probes import PROBE_BASES
    s, d, stored = fx["specular"], fx["diffuse"], PROBE_BASES[probes["irradiance"]]
    if s in bases.SPECULAR and d in bases.DIFFUSE and d != s:
        v.fail("effects.specular", f"{s} beside effects.diffuse: {d}: a frame lights from one directional basis; "
                                   f"give effects.diffuse {s} (or sh, probes) or another specular mode")
    if s in bases.SPECULAR and d == "probes" and stored.directional:
        others = " or ".join(n for n, b in PROBE_BASES.items() if not b.directional)
        v.fail("effects.specular", f"{s} beside probes storing {probes['irradiance']}: a frame lights from one "
                                   f"directional basis; give probes.irradiance {others}, or another specular mode")
    if s == "probes" and not stored.specular:
        v.fail("effects.specular", f"probes reads the radiance along the lobe from the probes' basis, and "
                                   f"probes.irradiance {probes['irradiance']} stores no specular lobe: give probes."
                                   f"irradiance {' or '.join(n for n, b in PROBE_BASES.items() if b.specular)} (a "
                                   "probes: section), or another specular mode")
    if s == "probes" and d in bases.DIFFUSE:
        v.fail("effects.specular", f"probes beside effects.diffuse: {d}: a frame lights from one directional basis; "
                                   "give effects.diffuse probes (or sh), or another specular mode")


def _resolve_lightmap(v: "_Validator", out: dict, raw: dict) -> None:
    """`effects.diffuse: lightmap` reads the scene's `lightmap` section (it must have one); the shade
    pass compiles one directional basis a frame (kernels/bases.h), so a lightmap storing one sits
    beside no other (the distant specular basis', the probes' that light what has no lightmap); the
    SH reading of an SH lightmap takes its coefficients' bands from effects.sh_bands' evaluation."""
    from iblbake.core import bases
    from iblbake.core.bases.probes import PROBE_BASES
    fx = out["effects"]
    if fx["diffuse"] != "lightmap":
        return
    if "lightmap" not in raw:
        v.fail("effects.diffuse", "lightmap reads the scene's lightmap: section, and it has none; add one "
                                  "(`lightmap: {}` takes the defaults; docs/manual.md 'Lightmaps') or give another "
                                  "diffuse mode")
    name = out["lightmap"]["basis"]
    mine = PROBE_BASES.get(name)
    stored = PROBE_BASES[out["probes"]["irradiance"]] if "probes" in raw else None
    if fx["specular"] in bases.SPECULAR and ((mine and mine.directional) or (stored and stored.directional)):
        v.fail("effects.specular", f"{fx['specular']} beside a lightmap or probes storing a directional basis: a frame "
                                   "lights from one directional basis; give lightmap.basis (and probes.irradiance) "
                                   "irradiance, sh_l1 or sh, or another specular mode")
    if mine and mine.directional and stored and stored.directional and (
            stored is not mine or mine.options(out["lightmap"]) != stored.options(out["probes"])):
        v.fail("lightmap.basis", f"{name} {mine.options(out['lightmap'])} beside probes storing {stored.name} "
                                 f"{stored.options(out['probes'])} (they light what has no lightmap): a frame lights "
                                 f"from one directional basis; give the probes the lightmap's basis and options, or "
                                 "probes.irradiance octahedral or sh")
    coeffs = {"sh_l1": 4}.get(name, mine.floats({}) if mine and not mine.directional and not mine.atlas else 0)
    if coeffs > fx["sh_bands"] ** 2:
        v.fail("effects.sh_bands", f"{fx['sh_bands']} evaluates fewer SH coefficients than lightmap.basis {name} "
                                   f"holds ({coeffs}); give {math.isqrt(coeffs)} or more")


def _resolve_lightmap_specular(v: "_Validator", out: dict, raw: dict) -> None:
    """`effects.specular: lightmap` reads the radiance along the lobe from the scene's lightmap (its
    section baked), of a basis that carries a lobe, beside no other directional basis (the shade
    pass compiles one basis a frame: kernels/bases.h): not a distant one, nor probes storing another."""
    from iblbake.core import bases
    from iblbake.core.bases.probes import PROBE_BASES
    fx = out["effects"]
    if fx["specular"] != "lightmap":
        return
    if "lightmap" not in raw:
        v.fail("effects.specular", "lightmap reads the lobe from the scene's lightmap: section, and it has none; add "
                                   "one (`lightmap: {basis: sg}`; docs/manual.md 'Lightmaps') or give another "
                                   "specular mode")
    name = out["lightmap"]["basis"]
    if name not in LIGHTMAP_LOBED:
        v.fail("effects.specular", f"lightmap reads the radiance along the lobe from the lightmap's basis, and "
                                   f"lightmap.basis {name} carries no lobe: give lightmap.basis "
                                   f"{' or '.join(LIGHTMAP_LOBED)}, or effects.specular prefiltered")
    mine, stored = PROBE_BASES[name], PROBE_BASES[out["probes"]["irradiance"]]
    if fx["diffuse"] in bases.DIFFUSE or (fx["diffuse"] == "probes" and stored.directional and (
            stored is not mine or mine.options(out["lightmap"]) != stored.options(out["probes"]))):
        v.fail("effects.specular", f"lightmap (lightmap.basis {name}) beside effects.diffuse {fx['diffuse']} of "
                                   "another directional basis: a frame lights from one; give effects.diffuse "
                                   "lightmap, sh, off (or probes storing the lightmap's basis and options)")


AUTO_SUN_LIGHTS = 4         # the lights `sun: auto` extracts: a sun, or studio's four lamps (bake/sun.py)


def has_probes(out: dict, raw: dict) -> bool:
    """Whether a scene has irradiance probes (a `probes:` section, or a frame that reads them) or
    reflection probes: what it bakes them from, whichever mode a frame or a study's rung reads
    (a volume baked by name and a frame reading it key the same panorama)."""
    fx = out["effects"]
    return "probes" in raw or "probes" in (fx["diffuse"], fx["specular"]) or bool(out["reflection_probes"])


def has_lightmap(out: dict, raw: dict) -> bool:
    """Whether a scene has a lightmap (a `lightmap:` section, or a frame that reads one): what it
    bakes one from, whichever mode a frame reads (a lightmap baked by name keys the same panorama)."""
    return "lightmap" in raw or "lightmap" in (out["effects"]["diffuse"], out["effects"]["specular"])


def _resolve_sun(out: dict, raw: dict) -> None:
    """`environment.sun: auto` (the default): extract where the scene has probes (has_probes) or a
    lightmap (has_lightmap), none elsewhere. A probe grid (or a capture read at one point) cannot
    hold the shadow edge of a compact light through a window: studio's lamps through a new user's
    window room left a sphere's lit side 1.7-1.9x bright at every seed and ray count, x1.02-1.08
    with the lamps lit per pixel, as engines light their dominant lights. A lightmap's texels hold
    a sun patch no sharper than themselves (a new user's two storeys under city: the frame 35% off
    with the sun in the atlas, 17% lit per pixel) and its rays find small lamps rarely: the corpus'
    interiors' lightmap frames under studio 7.0-15.6% -> 3.8-10.6% with the lights per pixel, under
    city 3.7-16.7% -> 3.3-14.0% (docs/manual.md "Irradiance probes in interiors", "Lightmaps"). Where
    auto extracts, sun_lights is AUTO_SUN_LIGHTS and sun_shadows soft unless the scene gives them
    (lamps are disks of 4-16 degrees: hard shadows would cut their penumbrae)."""
    env = out["environment"]
    if env["sun"] != "auto":
        return
    if not has_probes(out, raw) and not has_lightmap(out, raw):
        env["sun"] = "none"
        return
    given = raw.get("environment") if isinstance(raw.get("environment"), dict) else {}
    env["sun"] = "extract"
    if "sun_lights" not in given:
        env["sun_lights"] = AUTO_SUN_LIGHTS
    if "sun_shadows" not in given:
        env["sun_shadows"] = "soft"


def _resolve_specular_fits(out: dict, raw: dict) -> None:
    """A basis whose lobes serve the specular term (`specular: sg | ambient_dice`, or `specular:
    probes` from probes storing one) takes its SPECULAR_DEFAULTS (NNLS) for the options the scene
    leaves out: least squares rings negative around a sun, and the lobe clamped at 0 showed black
    patches beside white ones on metals (the sphere grid under city: 3.2% (sg) and 12% (ambient
    dice) of the metal spheres' pixels black; none with NNLS)."""
    from iblbake.core import bases
    s = out["effects"]["specular"]
    for section, name in (("effects", s), ("probes", out["probes"]["irradiance"] if s == "probes" else None)):
        given = raw.get(section) if isinstance(raw.get(section), dict) else {}
        for k, value in getattr(bases.BASES.get(name), "SPECULAR_DEFAULTS", {}).items():
            if k not in given:
                out[section][k] = value


def _resolve_probes(v: "_Validator", p: dict) -> None:
    """The probe grid's keys that decide it together: min with max, counts or spacing."""
    if (p["min"] is None) != (p["max"] is None):
        v.fail("probes.max" if p["max"] is None else "probes.min",
               "probes.min and probes.max go together (the box the probes span): give both min and max, or neither for an "
               "automatic grid")
    if p["min"] is not None and any(hi < lo for lo, hi in zip(p["min"], p["max"])):
        v.fail("probes.max", f"{p['max']} is below probes.min {p['min']} on some axis; give max >= min")
    if p["counts"] is not None and p["spacing"] is not None:
        v.fail("probes.spacing", "give probes.counts or probes.spacing, not both (each decides the grid)")


def _resolve_outputs(v: "_Validator", o: dict, folder: Path, outputs) -> list:
    """-o replaces output.frame; scene paths stay inside the scene folder. Returns what names
    each output in the overwrite guard's messages: -o, or the key with its line."""
    if outputs:
        o["frame"] = [os.path.abspath(p) for p in outputs]     # as given: a link is named, not its target
        o["frame_from_cli"] = True
    else:
        o["frame"] = [str(_resolve_inside(folder, p, "output.frame", v.where("output.frame")))
                      for p in (o["frame"] or [])]
    for p in o["frame"]:
        if Path(p).suffix.lower() not in FRAME_SUFFIXES:
            v.fail("output.frame", f"{p}: unsupported frame type; use .png (tone-mapped) or .exr (linear)")
    for a in AOVS:
        if o[a]:
            o[a] = str(_resolve_inside(folder, o[a], f"output.{a}", v.where(f"output.{a}")))
            if Path(o[a]).suffix.lower() != ".exr":
                v.fail(f"output.{a}", f"{o[a]}: AOVs are written as .exr")
    return [("-o" if o.get("frame_from_cli") else f"{v.where('output.frame')}: output.frame", p)
            for p in o["frame"]] + [(f"{v.where(f'output.{a}')}: output.{a}", o[a]) for a in AOVS if o[a]]


def named_input_files(sc: Scene) -> list:
    """(what, path) of every file rendering the scene reads: the scene itself, its panorama, its
    meshes (a .gltf's buffers and images beside it too) and textures."""
    from iblbake.scene.gltf import external_files

    d = sc.data
    named = [("the scene file", str(Path(sc.source).resolve())), ("the panorama", d["environment"]["path"])]
    for i, o in enumerate(d["objects"]):
        if "mesh" in o:
            named.append((f"the mesh of objects.{i}", o["mesh"]["path"]))
            named += [(f"a file of the mesh of objects.{i}", f) for f in external_files(o["mesh"]["path"])]
    named += [(f"materials.{name}.{k}", m[k]["path"]) for name, m in d["materials"].items()
              for k in m if k.endswith("_map") and m[k]]
    return named


def input_files(sc: Scene) -> list:
    """The paths of named_input_files, each once (for depfiles)."""
    return list(dict.fromkeys(p for _, p in named_input_files(sc)))



def replace_strings(value, mapping: dict):
    """`value` (nested dicts and lists) with every string found in `mapping` replaced by its value."""
    if isinstance(value, dict):
        return {k: replace_strings(x, mapping) for k, x in value.items()}
    if isinstance(value, list):
        return [replace_strings(x, mapping) for x in value]
    return mapping.get(value, value) if isinstance(value, str) else value


def with_files(sc: Scene, moved: dict) -> Scene:
    """The scene reading each file of `moved` (old path -> new path) from its new place: a worker
    on another machine renders a cell from its own copies of the files (same content)."""
    d = sc.data
    data = {**d, "environment": replace_strings(d["environment"], moved),
            "materials": replace_strings(d["materials"], moved),
            "objects": [replace_strings(o, moved) for o in d["objects"]]}
    return Scene(data, sc.source, sc.folder, sc.lines)
