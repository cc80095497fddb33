"""The scene schema: the field types and the table of every scene key, its type, default and
meaning. The validator (iblbake.scene.load) walks it, `render --help-schema` prints it
(schema_text) and docs/scene.md is generated from it (schema_markdown; regenerate with
`python -m iblbake.scene.schema > docs/scene.md`, or `make docs`; a test fails while it is stale).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Any

from iblbake.core import bases
from iblbake.core.bases.probes import PROBE_BASES
from iblbake.core.conventions import wrap_degrees

# what a lightmap texel can keep (render/lightmaps/bases.py): its own two, then every basis of the
# probes' registry that says it may (ProbeBasis.lightmap: not the octahedral atlas, not L1 Geomerics)
LIGHTMAP_BASES = ("irradiance", "sh_l1", *(n for n, b in PROBE_BASES.items() if b.lightmap))
# those whose lobe serves the specular term too (`effects.specular: lightmap`: a second set a texel)
LIGHTMAP_LOBED = tuple(n for n, b in PROBE_BASES.items() if b.lightmap and b.specular)

# Field types. Each checks one value and returns it normalised, or raises _Bad with the reason.


class _Bad(Exception):
    pass


@dataclass
class Num:
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False      # lo excluded (fov 0 is an error, radius must be > 0)
    integer: bool = False
    doc: str = ""
    angle: bool = False        # degrees: reduced into (-360, 360) exactly (conventions.wrap_degrees)

    def check(self, v):
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise _Bad(f"{v!r} is not a number")
        if self.integer and (not float(v).is_integer()):
            raise _Bad(f"{v!r} is not a whole number")
        if not math.isfinite(v):
            raise _Bad(f"{v!r} is not finite")
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            raise _Bad(f"{v!r} is out of range; give a value {'>' if self.lo_open else '>='} {self.lo:g}"
                       + (f" and <= {self.hi:g}" if self.hi is not None else ""))
        if self.hi is not None and v > self.hi:
            raise _Bad(f"{v!r} is out of range; give a value <= {self.hi:g}"
                       + (f" and {'>' if self.lo_open else '>='} {self.lo:g}" if self.lo is not None else ""))
        return int(v) if self.integer else wrap_degrees(v) if self.angle else float(v)

    def describe(self):
        rng = ""
        if self.lo is not None or self.hi is not None:
            lo = "" if self.lo is None else f"{self.lo:g}{' <' if self.lo_open else ' <='} "
            hi = "" if self.hi is None else f" <= {self.hi:g}"
            rng = f" ({lo}x{hi})"
        return ("integer" if self.integer else "number") + rng


@dataclass
class Vec:
    n: int = 3
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    nonzero: bool = False
    integer: bool = False
    positive: bool = False
    doc: str = ""
    angle: bool = False        # degrees: each reduced into (-360, 360) exactly

    def check(self, v):
        if not isinstance(v, (list, tuple)) or len(v) != self.n:
            raise _Bad(f"{v!r} is not a list of {self.n} numbers")
        out = []
        for x in v:
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                raise _Bad(f"{v!r} holds {x!r}, not a finite number")
            if self.integer and not float(x).is_integer():
                raise _Bad(f"{v!r} holds {x!r}, not a whole number")
            if self.lo is not None and x < self.lo:
                raise _Bad(f"{v!r} holds {x!r}; each value must be >= {self.lo:g}")
            if self.hi is not None and x > self.hi:
                raise _Bad(f"{v!r} holds {x!r}; each value must be <= {self.hi:g}")
            if self.positive and x <= 0:
                raise _Bad(f"{v!r} holds {x!r}; each value must be > 0")
            out.append(int(x) if self.integer else wrap_degrees(x) if self.angle else float(x))
        if self.nonzero and all(x == 0 for x in out):
            raise _Bad(f"{v!r} is the zero vector; give a direction")
        return out

    def describe(self):
        return f"[{', '.join(['x'] * self.n)}]" + (" (each >= %g)" % self.lo if self.lo is not None else "")


@dataclass
class Enum:
    choices: tuple
    default: Any = None
    doc: str = ""

    def check(self, v):
        if isinstance(v, bool) and "on" in self.choices:   # YAML reads `off` as False
            v = "on" if v else "off"
        if isinstance(v, bool) and "off" in self.choices and v is False:
            v = "off"
        if v not in self.choices:
            near = difflib.get_close_matches(str(v), [str(c) for c in self.choices], 1, 0.6)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise _Bad(f"{v!r} is not one of {' | '.join(map(str, self.choices))}{hint}")
        return v

    def describe(self):
        return " | ".join(map(str, self.choices))


@dataclass
class Bool:
    default: Any = False
    doc: str = ""

    def check(self, v):
        if not isinstance(v, bool):
            raise _Bad(f"{v!r} is not true or false")
        return v

    def describe(self):
        return "true | false"


@dataclass
class Str:
    default: Any = None
    doc: str = ""
    path: bool = False           # a file's path: no NUL (no file is named so; the OS refuses it)

    def check(self, v):
        if not isinstance(v, str) or not v:
            raise _Bad(f"{v!r} is not a non-empty string")
        if self.path and "\0" in v:
            raise _Bad(f"{v!r} holds a NUL character, which no path can")
        return v

    def describe(self):
        return "string"


@dataclass
class OneOf:
    """The first alternative that accepts the value (e.g. a size: number or [w, h])."""
    alternatives: tuple
    default: Any = None
    doc: str = ""

    def check(self, v):
        reasons = []
        for alt in self.alternatives:
            try:
                return alt.check(v)
            except _Bad as e:
                reasons.append(str(e))
        # the complaint of the one alternative of the value's kind (a number's range, a list's
        # length), else what the value may be; not every alternative's complaint joined ("0 is not
        # one of unbounded and 0 is out of range")
        own = [r for alt, r in zip(self.alternatives, reasons) if _of_its_kind(alt, v)]
        if len(own) == 1:
            raise _Bad(own[0])
        kinds = [a.describe() for a in self.alternatives]
        said = f"neither {kinds[0]} nor {kinds[1]}" if len(kinds) == 2 else f"none of {', '.join(kinds[:-1])} or {kinds[-1]}"
        raise _Bad(f"{v!r} is {said}")

    def describe(self):
        return " or ".join(a.describe() for a in self.alternatives)


def _of_its_kind(alt, v) -> bool:
    """Whether v is of the Python type alternative `alt` reads (a number for Num, a list for Vec,
    a string for Enum, ...), whatever its value."""
    if isinstance(alt, Enum):
        return isinstance(v, str) or (isinstance(v, bool) and bool({"on", "off"} & set(alt.choices)))
    kinds = {Num: (int, float), Vec: (list, tuple), Bool: (bool,), Str: (str,), ColorKey: (dict,)}.get(type(alt))
    if kinds is None:
        return False
    return (bool in kinds) if isinstance(v, bool) else isinstance(v, kinds)


@dataclass
class ColorKey:
    """{color: [r, g, b]}: the same as the bare list, spelled as the docs say it."""
    doc: str = ""

    def check(self, v):
        if not isinstance(v, dict) or list(v) != ["color"]:
            raise _Bad(f"{v!r} is not {{color: [r, g, b]}}")
        return Vec(n=3, lo=0.0).check(v["color"])

    def describe(self):
        return "{color: [r, g, b]}"


@dataclass
class Section:
    fields: dict
    required: tuple = ()
    exclusive: tuple = ()        # exactly one of these keys (camera projection, object kind)
    doc: str = ""
    optional: bool = False       # absent: None (a material's texture), not a section of defaults


@dataclass
class MapOf:
    """A mapping from user names to sections (materials)."""
    section: Section
    doc: str = ""


@dataclass
class ListOf:
    section: Section
    doc: str = ""


@dataclass
class Raw:
    """A mapping or list kept as written (the sweep axes, validated by iblbake.study.sweep)."""
    default: Any = None
    doc: str = ""
    kinds: tuple = (dict, list)

    def check(self, v):
        if not isinstance(v, self.kinds):
            raise _Bad(f"{v!r} is not a mapping or a list")
        return v

    def describe(self):
        return "mapping"


@dataclass
class StrList:
    default: Any = None
    doc: str = ""
    what: str = "path"
    empty: bool = False          # [] allowed (none: `exclude: []`)

    def check(self, v):
        items = [v] if isinstance(v, str) and v else v
        if not (isinstance(items, list) and (items or self.empty) and all(isinstance(x, str) and x for x in items)):
            raise _Bad(f"{v!r} is not a {self.what} or a list of {self.what}s")
        if self.what == "path" and any("\0" in x for x in items):
            raise _Bad(f"{next(x for x in items if chr(0) in x)!r} holds a NUL character, which no path can")
        return list(items)

    def describe(self):
        return f"{self.what} or [{self.what}s]"


VEC3 = dict(n=3)
MAX_BOUNCES = 1 << 16


def bounces_field(doc: str) -> OneOf:
    """A path's scattering count: unbounded (Russian roulette) or 1 .. MAX_BOUNCES."""
    return OneOf((Enum(("unbounded",)), Num(None, 1, MAX_BOUNCES, integer=True)), default="unbounded", doc=doc)

CAMERA_COMMON = {
    "position": Vec(**VEC3, doc="camera position (world space, +y up)"),
    "look_at": Vec(**VEC3, default=[0.0, 0.0, 0.0], doc="point the camera looks at"),
    "up": Vec(**VEC3, default=[0.0, 1.0, 0.0], nonzero=True, doc="up direction"),
}

def _map_section(doc: str, **extra) -> Section:
    """A material's texture: an image and how it is read (KHR_texture_transform, a glTF sampler)."""
    return Section(required=("path",), doc=doc, optional=True, fields={
        "path": Str(path=True, doc="PNG or JPEG (8 or 16 bits, any size); relative to the scene file"),
        "texcoord": Num(0, 0, 1, integer=True, doc="the mesh's TEXCOORD set (spheres: the panorama mapping "
                                                   "u = 0.5 - atan2(x, z)/(2 pi), v = acos(y)/pi; planes: across "
                                                   "their width and depth, 1 per unit if infinite)"),
        "uv_offset": Vec(n=2, default=[0.0, 0.0], doc="KHR_texture_transform offset"),
        "uv_scale": Vec(n=2, default=[1.0, 1.0], doc="KHR_texture_transform scale"),
        "uv_rotation": Num(0.0, angle=True, doc="KHR_texture_transform rotation, degrees (counter-clockwise in UV)"),
        "wrap": Enum(("repeat", "clamp", "mirror"), "repeat", doc="outside [0, 1]"),
        "filter": Enum(("linear", "nearest"), "linear", doc="linear: bilinear and trilinear mipmaps; nearest: "
                                                           "nearest texel and mip level"),
        **extra,
    })


# gtao's search, as benchmarks/tune_gtao.py chose it: the lowest AO error against 1024-ray
# raytraced AO over the two example scenes of that script (docs/manual.md: "Ambient occlusion")
GTAO_DEFAULTS = {"slices": 2, "steps": 6, "radius_scale": 2.0, "falloff": 0.6, "power": 1.3, "denoise": 2,
                 "resolution": "half"}

SCHEMA = Section(doc="a scene", required=("environment",), fields={
    "camera": Section(doc="the camera", exclusive=("perspective", "orthographic"), fields={
        "perspective": Section(required=("position",), doc="pinhole camera", fields={
            **CAMERA_COMMON,
            "fov_y": Num(40.0, 0.0, 179.0, lo_open=True, doc="vertical field of view, degrees"),
        }),
        "orthographic": Section(required=("position", "width"), doc="parallel projection", fields={
            **CAMERA_COMMON,
            "width": Num(None, 0.0, lo_open=True, doc="width of the view in world units"),
        }),
        "resolution": Vec(n=2, default=[640, 360], integer=True, positive=True, hi=16384,
                          doc="[width, height] in pixels"),
        "spp": Num(1, 1, 1024, integer=True, doc="primary samples per pixel (anti-aliasing)"),
    }),
    "environment": Section(required=("path",), doc="the HDR panorama lighting the scene", fields={
        "path": Str(path=True, doc="equirectangular panorama (EXR, HDR, any format iblbake reads); relative to the scene file"),
        "intensity": Num(1.0, 0.0, doc="radiance scale"),
        "rotation_y": Num(0.0, angle=True, doc="rotate the panorama about +y, degrees (+x towards -z)"),
        "background": OneOf((Enum(("show", "hide")), Vec(n=3, lo=0.0), ColorKey()), default="show",
                            doc="show the panorama, hide it (black), or a constant [r, g, b]"),
        "blur": Num(0.0, 0.0, 1.0, doc="show the background through the prefiltered level of this roughness (0: sharp)"),
        "nonfinite": Enum(("error", "zero", "clamp"), "error", doc="NaN/Inf texels: fail, zero or clamp"),
        "negative": Enum(("keep", "clamp", "error"), "keep", doc="negative texels: keep, clamp to 0, or fail"),
        "transfer": Enum(("auto", "srgb", "linear"), "auto",
                         doc="texels to linear: auto (an 8/16-bit PNG or JPEG from sRGB or what it declares; "
                             "float images as stored), srgb, or linear"),
        "layout": Enum(("auto", "equirect", "hcross", "vcross", "hstrip", "vstrip", "ktx2"), "auto",
                       doc="what path holds: an equirect panorama or a cube map (a cross, a strip of six faces, "
                           "KTX2), resampled to equirect; auto by .ktx2, then the aspect ratio"),
        "primaries": Enum(("auto", "keep", "convert"), "auto",
                          doc="EXR chromaticities other than Rec.709: keep the values and say so (auto), keep them "
                              "silently (keep), or convert to Rec.709/D65"),
        "sun": Enum(("auto", "none", "extract"), "auto",
                    doc="extract: the panorama's sun (a compact region 1e4 x brighter than the median, or holding 4% of "
                        "its energy) leaves the "
                        "panorama and comes back as a directional light of exactly its energy, so it casts shadows; "
                        "auto: extract where the scene has irradiance probes (a probes: section, or a frame that "
                        "reads them), reflection probes or a lightmap (a lightmap: section, or a frame that reads "
                        "one; neither a probe grid nor a lightmap's texels hold a sun's or lamp's shadow edge "
                        "through a window: docs/manual.md 'Irradiance probes in interiors'), with sun_lights 4 and "
                        "soft shadows unless given; none elsewhere"),
        "sun_shadows": Enum(("hard", "soft", "none"), "hard", doc="the extracted sun's shadows (soft where sun: auto "
                                                                 "extracts, unless given)"),
        "sun_shadow_samples": Num(16, 1, 4096, integer=True,
                                  doc="soft sun_shadows: shadow rays per pixel sample over each extracted light's "
                                      "disk (as a light's shadow_samples; a softbox's penumbra grainy at 16 and "
                                      "1 spp)"),
        "sun_lights": Num(1, 1, 8, integer=True, doc="extract: how many compact bright regions leave the panorama as directional "
                                       "lights, brightest first: 1 the sun (at most 6 degrees); more takes lamps and "
                                       "softboxes too (up to 20 degrees, each 2% of the energy or more: studio's "
                                       "four lamps), each a disk whose soft shadows spread its penumbra (4 where "
                                       "sun: auto extracts, unless given)"),
    }),
    "materials": MapOf(doc="named materials (glTF 2.0's metallic-roughness model)", section=Section(
        doc="a metallic-roughness material", fields={
            "base_color": Vec(**VEC3, default=[0.8, 0.8, 0.8], lo=0.0, hi=1.0,
                              doc="linear RGB albedo / F0 of metals (times base_color_map)"),
            "metallic": Num(0.0, 0.0, 1.0, doc="0 dielectric (F0 = 0.04), 1 metal (F0 = base_color); times the "
                                               "map's blue"),
            "roughness": Num(0.5, 0.0, 1.0, doc="perceptual roughness r; alpha = r^2; times the map's green"),
            "emissive": Vec(**VEC3, default=[0.0, 0.0, 0.0], lo=0.0, doc="emitted radiance, linear RGB (times "
                                                                         "emissive_map)"),
            "specular": Num(1.0, 0.0, 1.0, doc="KHR_materials_specular's specularFactor: a dielectric's specular "
                                               "weight, its F90 (0: pure Lambert, no GGX lobe and no Fresnel on "
                                               "the diffuse)"),
            "specular_color": Vec(**VEC3, default=[1.0, 1.0, 1.0], lo=0.0,
                                  doc="specularColorFactor: a dielectric's F0 is min(0.04 x this, 1) x specular"),
            "alpha": Num(1.0, 0.0, 1.0, doc="alpha_mode mask: coverage factor (times the base map's alpha)"),
            "alpha_mode": Enum(("opaque", "mask"), "opaque", doc="mask: cut out where alpha < alpha_cutoff"),
            "alpha_cutoff": Num(0.5, 0.0, 1.0, doc="alpha_mode mask: the threshold"),
            "double_sided": Bool(True, doc="false: surfaces exist only on their front (a sphere's and plane's "
                                           "normal side, a triangle's counter-clockwise one), as glTF's doubleSided"),
            "base_color_map": _map_section("base colour texture (sRGB), RGB times base_color, A times alpha"),
            "metallic_roughness_map": _map_section("metallic (blue) and roughness (green) texture, linear"),
            "normal_map": _map_section("tangent-space normal texture (glTF's: +y up the image)",
                                       scale=Num(1.0, doc="the normal's x and y scale")),
            "occlusion_map": _map_section("ambient occlusion texture (red), on the image-based light only",
                                          strength=Num(1.0, 0.0, 1.0, doc="1 + strength (red - 1)")),
            "emissive_map": _map_section("emissive texture (sRGB), times emissive"),
        })),
    "objects": ListOf(doc="what is in the scene", section=Section(
        exclusive=("sphere", "plane", "mesh"), doc="one object", fields={
            "sphere": Section(required=("radius",), doc="analytic sphere", fields={
                "center": Vec(**VEC3, default=[0.0, 0.0, 0.0], doc="centre"),
                "radius": Num(None, 0.0, lo_open=True, doc="radius (> 0)"),
            }),
            "plane": Section(doc="analytic plane, two-sided", fields={
                "point": Vec(**VEC3, default=[0.0, 0.0, 0.0], doc="a point on the plane (the centre of a finite one)"),
                "normal": Vec(**VEC3, default=[0.0, 1.0, 0.0], nonzero=True, doc="plane normal"),
                "size": OneOf((Num(None, 0.0, lo_open=True), Vec(n=2, positive=True)), default=None,
                              doc="side length, or [width, depth]; omitted: infinite"),
            }),
            "mesh": Section(required=("path",), doc="triangle mesh: glTF/GLB (with its materials and textures), "
                                                    "OBJ, PLY, STL (geometry and UVs, through trimesh)", fields={
                "path": Str(path=True, doc="GLB, glTF, OBJ, PLY or STL; relative to the scene file"),
                "translate": Vec(**VEC3, default=[0.0, 0.0, 0.0], doc="translation"),
                "rotate": Vec(**VEC3, default=[0.0, 0.0, 0.0], angle=True, doc="rotation about x, then y, then z, degrees"),
                "scale": OneOf((Num(None, 0.0, lo_open=True), Vec(n=3, positive=True)), default=1.0,
                               doc="uniform scale or [sx, sy, sz] (> 0)"),
                "smooth": Enum(("auto", "on", "off"), "auto",
                               doc="shading normals: auto = the file's vertex normals if it has them, else faceted"),
            }),
            "material": Str(doc="name of a material in `materials`; a glTF/GLB mesh without one is shaded "
                                "with the file's own materials"),
            "name": Str(doc="what messages and reflection_probes.N.exclude call the object (default: objects.N, "
                            "its index)"),
            "solid": OneOf((Enum(("auto",)), Bool()), default="auto",
                           doc="whether the object bounds a solid, whose inside the irradiance probes treat as inside "
                               "geometry (docs/conventions.md \"Sides\"): auto = a sphere, or a mesh's closed "
                               "(watertight, consistently wound) parts, unless the camera is inside them (a room); "
                               "false: a shell, a front face to probes from either side (double-sided only)"),
            "reflection_captures": Bool(True, doc="seen by the reflection probes' captures (false: their first "
                                                  "rays pass through it, as Unreal's Visible in Reflection Captures "
                                                  "and Unity's culling mask; it still shadows and reflects light "
                                                  "further along the paths)"),
            "lightmap": Bool(True, doc="gets a lightmap where the scene has one (a mesh, sphere or finite "
                                       "plane); false: a dynamic object, lit by the irradiance probes (else the "
                                       "panorama's SH) under `effects.diffuse: lightmap`, still met by the "
                                       "lightmap's rays"),
        })),
    "lights": ListOf(doc="analytic lights in the units of glTF's KHR_lights_punctual, added to the IBL and "
                         "shaded with its BRDF", section=Section(
        exclusive=("directional", "point", "spot"), doc="one light", fields={
            "directional": Section(doc="a distant light (the sun)", fields={
                "direction": Vec(**VEC3, default=[0.0, -1.0, 0.0], nonzero=True,
                                 doc="the way the light travels, towards the scene (a glTF light node's -Z)"),
                "color": Vec(**VEC3, default=[1.0, 1.0, 1.0], lo=0.0, doc="linear RGB"),
                "illuminance": Num(1.0, 0.0, doc="lux (lm/m^2) on a surface facing it"),
                "angular_diameter": Num(0.0, 0.0, 90.0, doc="degrees (the sun: 0.53); a disk this wide "
                                                           "gives soft shadows their penumbra"),
            }),
            "point": Section(required=("position",), doc="a light at a point, or a sphere of `radius`", fields={
                "position": Vec(**VEC3, doc="centre"),
                "color": Vec(**VEC3, default=[1.0, 1.0, 1.0], lo=0.0, doc="linear RGB"),
                "intensity": Num(1.0, 0.0, doc="candela (lm/sr)"),
                "radius": Num(0.0, 0.0, doc="sphere light radius (0: a point); soft shadows sample it"),
                "range": Num(None, 0.0, lo_open=True, doc="falloff windowed to 0 at this distance, as "
                                                          "KHR_lights_punctual recommends; omitted: infinite"),
            }),
            "spot": Section(required=("position",), doc="a point light in a cone", fields={
                "position": Vec(**VEC3, doc="apex"),
                "direction": Vec(**VEC3, default=[0.0, -1.0, 0.0], nonzero=True, doc="the cone's axis, the way "
                                                                                    "the light travels"),
                "color": Vec(**VEC3, default=[1.0, 1.0, 1.0], lo=0.0, doc="linear RGB"),
                "intensity": Num(1.0, 0.0, doc="candela (lm/sr) on the axis"),
                "inner_cone_angle": Num(0.0, 0.0, 90.0, doc="degrees from the axis: full intensity inside"),
                "outer_cone_angle": Num(45.0, 0.0, 90.0, lo_open=True, doc="degrees from the axis: dark outside"),
                "radius": Num(0.0, 0.0, doc="sphere light radius (0: a point)"),
                "range": Num(None, 0.0, lo_open=True, doc="as for point"),
            }),
            "shadows": Enum(("hard", "soft", "none"), "hard",
                            doc="hard: one shadow ray to the light's centre; soft: shadow_samples rays over its "
                                "disk or sphere; none"),
            "shadow_samples": Num(16, 1, 4096, integer=True, doc="soft: rays per pixel sample (stratified, seeded)"),
        })),
    "probes": Section(doc="the irradiance probe volume (DDGI) that `effects.diffuse: probes` reads and `iblbake probes` "
                          "bakes; lengths in units of the probe spacing are of its smallest axis", fields={
        "min": Vec(**VEC3, doc="the probe box's lower corner (with max: the box cut into cells, a probe at each "
                               "cell's centre, half a cell in from its faces; omitted: auto, cubic cells whose probes "
                               "overhang the scene's bounds by at least half a cell)"),
        "max": Vec(**VEC3, doc="the probe box's upper corner"),
        "counts": OneOf((Num(None, 1, 256, integer=True), Vec(**VEC3, integer=True, lo=1, hi=256)), default=None,
                        doc="probes along x, y, z, or N: N along the longest axis and as many as keep the "
                            "cells near cubes along the others (omitted: from spacing, else the scene's interior "
                            "scale, docs/conventions.md 'Irradiance probes'); an automatic grid takes N >= 3 (or "
                            ">= 2 per axis), min and max >= 2 along an axis they differ on; at most 1048576 probes"),
        "spacing": Num(None, 0.0, lo_open=True, doc="the distance between probes, where counts is omitted (omitted too: "
                                                    "half the typical free distance of rays in the scene's enclosed "
                                                    "spaces, the whole scene's grid or a min/max box's, at most "
                                                    "16384 probes, coarser above and said)"),
        "rays": Num(1024, 16, 1 << 16, integer=True,
                    doc="rays per probe, one path each (a spherical Fibonacci set, randomly rotated; DDGI traces "
                        "256 a frame and accumulates frames, a bake takes them at once: an unextracted sun's "
                        "visibility needs them)"),
        "target_noise": Num(0.3, 0.0, 1.0, doc="adaptive rays (0: off): a live probe whose irradiance's "
                                                "relative standard error after its rays (the spread over 7 interleaved "
                                                "batches of them, at the six axis directions) is over half this traces "
                                                "as many rays again in fresh directions, and again, up to max_rays; its "
                                                "irradiance and distances the mean over all of them, each round "
                                                "weighed in from 0 at half this to 1 at it (docs/manual.md)"),
        "max_rays": Num(None, 0, 1 << 19, integer=True,
                        doc="adaptive rays: the most rays a noisy probe takes, rounded down to rays times a power "
                            "of two (omitted: 8 x rays; 0, or under twice rays: off)"),
        "bounces": bounces_field("how many times the light a probe ray brings back may have scattered: unbounded "
                                 "(the reference's paths, Russian roulette), or N (1: the surfaces the probe sees, "
                                 "lit directly)"),
        "irradiance": Enum(tuple(PROBE_BASES), "octahedral",
                           doc="what each probe stores (core/bases/probes.py; a directional basis: docs/conventions.md "
                               "'Directional bases', its options the probes' keys of the effects' names): " + "; ".join(f"`{n}`: {b.doc}" for n, b in PROBE_BASES.items())),
        **{k: Enum(choices, default, doc=doc + " (the probes' basis)") for b in PROBE_BASES.values()
           for k, (choices, default, doc) in b.option_specs.items()},
        "irradiance_texels": Num(6, 2, 64, integer=True, doc="octahedral irradiance: interior texels per side (DDGI: 6; "
                                                              "the atlas adds a 1-texel border)"),
        "distance_texels": Num(14, 2, 64, integer=True, doc="distance moments: interior texels per side (DDGI: 14)"),
        "distance_exponent": Num(50.0, 1.0, 1000.0, doc="sharpness of the distance moments' cosine weights (RTXGI: 50)"),
        "visibility": Bool(True, doc="DDGI's weights: wrap shading and the Chebyshev test on the distance moments, "
                                     "so light does not leak through walls (false: trilinear interpolation alone)"),
        "normal_bias": Num(0.25, 0.0, 1.0, doc="visibility: the sample point moved along the normal (spacing units; "
                                                "0.1 let a slab of no thickness leak the storey above onto its underside)"),
        "view_bias": Num(0.1, 0.0, 1.0, doc="visibility: the sample point moved towards the viewer (spacing units)"),
        "relocation": Bool(True, doc="move a probe out of geometry or away from a surface it nearly touches, at most "
                                     "45% of a cell (RTXGI's relocation)"),
        "classification": Bool(True, doc="switch off a probe inside geometry or with no surface in its cells "
                                         "(RTXGI's classification): it is neither blended nor sampled"),
        "backface_threshold": Num(0.25, 0.0, 1.0, doc="the share of a probe's rays meeting back faces above which "
                                                       "it is inside geometry"),
        "min_frontface_distance": Num(0.4, 0.0, 0.45, doc="relocation: the nearest front face a probe may keep "
                                                           "(spacing units; a probe just behind a floor sees it at "
                                                           "grazing angles, where the distance moments' variance "
                                                           "lets the floor's far side through)"),
        "seed": Num(1, 0, 2**31 - 1, integer=True, doc="random seed of the rays' rotation and paths"),
    }),
    "lightmap": Section(doc="the static geometry's lightmap (iblbake.render.lightmaps: a second UV set, its texels "
                            "baked by the path tracer as irradiance and a directional basis; docs/manual.md "
                            "'Lightmaps')", fields={
        "basis": Enum(LIGHTMAP_BASES, "sh_l1",
                      doc="what each texel keeps beside its irradiance (render/lightmaps/bases.py): `irradiance` "
                          "(none: a non-directional lightmap), `sh_l1` (L1 SH read exactly at the texel's normal), "
                          "or an irradiance probes' basis (core/bases/probes.py; its options the probes' keys); "
                          "`effects.diffuse: lightmap` reads it at the shading normal (a normal map's): "
                          + "; ".join(f"`{n}`: {b.doc}" for n, b in PROBE_BASES.items() if b.lightmap)),
        **{k: Enum(choices, default, doc=doc + " (the lightmap's basis)") for b in PROBE_BASES.values()
           for k, (choices, default, doc) in b.option_specs.items()},
        "texels_per_unit": Num(8.0, 0.0, lo_open=True, doc="texels per world unit along each side of a surface (the "
                                                           "atlas' density; xatlas packs the charts at it)"),
        "samples": Num(1024, 16, 1 << 16, integer=True, doc="rays per texel over its hemisphere, one path each "
                                                            "(stratified: the nearest square below is taken; a room "
                                                            "lit through a small opening needs many: the corridor's "
                                                            "far end was 13-17% bright at 144, within 4% at 1024)"),
        "bounces": bounces_field("how many times the light a texel's ray brings back may have scattered: unbounded "
                                 "(the reference's paths), or N"),
        "max_texels": Num(4194304, 1, 1 << 28, integer=True,
                          doc="the largest atlas baked: a density whose estimate (area x density^2 over 70% use) "
                              "passes it is refused before anything is packed"),
        "seed": Num(1, 0, 2**31 - 1, integer=True, doc="random seed of the texels' rays and paths"),
    }),
    "reflection_probes": ListOf(doc="local reflection probes (Lagarde and Zanuttini 2012): radiance captured by the "
                                    "path tracer at a point, prefiltered as the distant chain, read by `specular: "
                                    "prefiltered` inside each probe's influence with parallax correction",
                                section=Section(required=("position",), doc="one probe", fields={
        "position": Vec(**VEC3, doc="where the probe captures (inside its influence)"),
        "shape": Enum(("box", "sphere"), "box", doc="the influence and parallax proxy: a box (min, max) or a sphere "
                                                    "(radius about position)"),
        "min": Vec(**VEC3, doc="box: the influence's lower corner"),
        "max": Vec(**VEC3, doc="box: the influence's upper corner"),
        "radius": Num(None, 0.0, lo_open=True, doc="sphere: the influence's radius"),
        "parallax": Bool(True, doc="read the capture where the reflected ray leaves the proxy (false: as if the "
                                   "captured surroundings were infinitely far, a distant probe)"),
        "blend": Num(0.1, 0.0, 1.0, doc="the share of each half extent (or of the radius) beyond the influence over "
                                        "which the probe fades out (inside it, the probe's capture alone)"),
        "taps": Num(0, 0, 256, integer=True, doc="parallax probes: read the material's true GGX lobe in this many "
                                                 "directions, each corrected to where it leaves the proxy, filtered "
                                                 "over its share of the lobe, the sky along each where the point sees "
                                                 "it open (costs that many reads of four chains a pixel; 64 for a "
                                                 "metal object under compact key lights). 0: one read a lobe about the "
                                                 "reflected ray, in grazing_taps taps at grazing views and where "
                                                 "the lobe straddles an opening's edge"),
        "grazing_taps": Num(64, 0, 256, integer=True,
                            doc="parallax probes with `taps: 0`: read the lobe in this many taps where the view "
                                "grazes the surface (all of the reading below NoV 0.4, blended into one read up to "
                                "0.8), and where the lobe straddles an opening's edge at a point off the probe "
                                "(blended by a weight), one read elsewhere: there the split sum's lobe about the "
                                "reflected ray misses the material's, and one read spreads a lamp seen inside a "
                                "window's edge over all the point sees open (the corpus' metal objects within 10% "
                                "on every half, 13-20% off on four with one read; 64: a rough gold sphere in a room "
                                "with two windows under forest 15% off on a half with 32). 0: one read everywhere"),
        "size": Num(128, 4, 2048, integer=True, doc="capture height in texels (an equirect of 2 size x size; the "
                                                   "prefiltered chain's base, effects.prefilter.size ignored)"),
        "samples": Num(64, 1, 1 << 16, integer=True, doc="paths per capture texel (stratified in the texel)"),
        "bounces": bounces_field("how many times the light a capture ray brings back may have scattered (1: the "
                                 "surfaces it sees, lit directly)"),
        "seed": Num(1, 0, 2**31 - 1, integer=True, doc="random seed of the capture's paths"),
        "exclude": StrList(what="name", empty=True, doc="objects (their names, or objects.N) this probe's capture looks through: a probe at "
                               "a reflective object's centre excludes that object to capture its surroundings. Only "
                               "the capture's own view (each texel's first ray) passes through them: the paths behind "
                               "it still meet them, so a floor keeps their shadow and the light they throw"),
    })),
    "effects": Section(doc="what the renderer simulates; nothing else is baked, compiled or run", fields={
        "diffuse": Enum(("sh",) + bases.DIFFUSE + ("probes", "lightmap", "reference", "off"), "sh",
                        doc="diffuse IBL: SH irradiance of the panorama, another directional basis of it ("
                            + ", ".join(f"`{n}`: {bases.BASES[n].TITLE}" for n in bases.DIFFUSE)
                            + "; docs/conventions.md), irradiance probes (`probes`: the light between surfaces "
                              "too), the scene's lightmap (`lightmap`: its `lightmap` section baked, read at each "
                              "pixel's UV1; what has none reads the probes, else the panorama's SH), Monte Carlo "
                              "reference, or none"),
        "sh_bands": Num(3, 1, 8, integer=True, doc="SH bands for diffuse: sh (3 = 9 coefficients)"),
        "sh_window": Enum(("none", "hann", "lanczos"), "none", doc="SH ringing window"),
        **{k: Enum(choices, default, doc=doc) for n in bases.DIFFUSE
           for k, (choices, default, doc) in bases.BASES[n].OPTIONS.items()},
        "specular": Enum(("importance", "prefiltered", "lobe") + bases.SPECULAR + ("probes", "lightmap", "reference",
                                                                                "off"),
                         "prefiltered",
                         doc="specular IBL: runtime GGX importance sampling (Colbert and Krivanek 2007), split sum, "
                             "lobe (K visible-normal samples reading the prefiltered chain), a directional basis ("
                             + ", ".join(f"`{n}`: {bases.BASES[n].TITLE}" for n in bases.SPECULAR)
                             + ": the split sum with the basis's radiance along the lobe in place of the chain, its "
                               "options the effects' keys, the same basis as a basis diffuse; docs/conventions.md "
                               "'Directional bases'), the irradiance probes' basis (`probes`: the same from the probes "
                               "around a point, probes.irradiance one of "
                             + ", ".join(bases.SPECULAR) + "; the distant chain outside them), the lightmap's "
                               "(`lightmap`: the same from a second set of the texels' coefficients fitted for the "
                               "radiance, beside `diffuse: lightmap` with lightmap.basis one of " + ", ".join(bases.SPECULAR)
                             + "; the distant chain on what has none), Monte Carlo reference, none"),
        "samples": Num(40, 1, 65536, integer=True, doc="importance: GGX samples per pixel"),
        "mip_bias": Num(1.0, -16.0, 16.0, doc="importance: added to each sample's mip level (Krivanek and "
                                              "Colbert: 1, closer to the reference; 0: none)"),
        "force_mip0": Bool(False, doc="importance: read level 0 for every sample (counting-reflections check)"),
        "normalize": Enum(("total", "accepted"), "total",
                          doc="importance: divide by all N samples (unbiased) or by the accepted ones (as many real-time shaders do)"),
        "prefilter": Section(doc="prefiltered: how the chain is baked (as `iblbake mips`)", fields={
            "method": Enum(("auto", "spectral", "convolve", "fis"), "auto", doc="see iblbake mips --method"),
            "samples": Num(256, 1, 1 << 20, integer=True, doc="fis samples per texel"),
            "size": Num(None, 1, 8192, integer=True, doc="base height of the equirect chain (default: source height)"),
            "levels": Num(13, 2, 32, integer=True, doc="levels K, roughness k/(K-1); between levels the chain "
                                                          "mixes two blurs (city, r = 0.3: 26% off the reference at "
                                                          "7 levels, 12.1% at 13, the split sum's own floor 12.0%)"),
            "level_sizes": Enum(("lobe", "halving"), "lobe",
                                doc="level heights: lobe (texels no wider than alpha/16, up to size: the exact split "
                                    "sum within 1%) or halving (size >> k, a mip chain: 2-4% off at r = 0.25 and 1)"),
            "min_size": Num(32, 1, 8192, integer=True, doc="smallest level height (bilinear lookups in an 8-row "
                                                          "level of a wide lobe are 2% off the exact split sum)"),
            "lod_bias": Num(1.0, -16.0, 16.0, doc="fis level bias"),
            "dominant_direction": Bool(True, doc="read the chain between N and R (Lagarde 2014), not at R: "
                                                 "closer to the reference on rough metals"),
            "dfg_size": Num(128, 2, 4096, integer=True, doc="DFG table size"),
            "dfg_samples": Num(4096, 1, 1 << 20, integer=True, doc="GGX samples per DFG texel"),
        }),
        "lobe": Section(doc="lobe: the split sum's chain and DFG table, read along the real lobe", fields={
            "samples": Num(4, 1, 256, integer=True,
                           doc="K visible-normal samples per pixel, each reading the chain at its share of the lobe"),
            "spread": Num(2.0, 0.0625, 1024.0, doc="solid angle each sample reads, in units of its share "
                                                    "1 / (K pdf) of the lobe (> 1: neighbouring samples overlap)"),
        }),
        "reference": Section(doc="reference modes: progressive Monte Carlo with MIS", fields={
            "max_samples": Num(1024, 1, 1 << 20, integer=True, doc="sample budget per pixel"),
            "target_noise": Num(0.002, 0.0, 1.0, doc="stop when the frame's relative standard error is below this"),
            "batch": Num(None, 1, 4096, integer=True, doc="samples per pixel per progressive pass (omitted: 32 on "
                                                          "a CPU, 256 on a GPU, whose launches cost more)"),
            "seed": Num(1, 0, 2**31 - 1, integer=True, doc="random seed (renders are reproducible)"),
            "visibility": Bool(True, doc="trace a shadow ray for every sample: the occluded integral (false: "
                                         "every object lit as if alone)"),
            "bounces": bounces_field("how many times a path may scatter: unbounded (Russian roulette from bounce 4, "
                                 "unbiased: the converged answer), N, or 1, the environment's direct light (no "
                                 "interreflection, no light from emissive surfaces); with visibility false, 1"),
            # removed: older scene files name it; they render as before, with a note (render/plan.py)
            "paths": Enum(("auto", "megakernel", "wavefront"), None,
                          doc="removed: every reference runs its paths as one kernel per sample (the megakernel; "
                              "the wavefront, the same estimator, was slower on every device measured). Still "
                              "accepted, with a note, so older scene files render as before; delete it"),
        }),
        "ssr": Enum(("off", "on"), "off", doc="stochastic screen-space reflections (Stachowiak 2015) over the split "
                                             "sum (specular: prefiltered): GGX rays marched through the frame's Hi-Z, its own "
                                             "lit radiance where they hit"),
        "ssr_settings": Section(doc="ssr: the march", fields={
            "max_roughness": Num(0.5, 0.0, 1.0, doc="surfaces rougher than this keep the probes' or panorama's "
                                                    "reflection (faded over its last fifth)"),
            "thickness": OneOf((Enum(("auto",)), Num(None, 0.0, lo_open=True)), default="auto",
                               doc="how far behind the depth buffer a candidate hit may lie (along the view): auto = "
                                   "1% of the scene's extent (the diagonal of the bounds of its geometry and the "
                                   "camera; 0.1 where only infinite planes bound it), so a scaled scene gives the "
                                   "same frame, or scene units; a candidate is kept only where the ray crosses the "
                                   "hit surface's own plane within a pixel"),
            "steps": Num(64, 1, 4096, integer=True, doc="march iterations per ray (Hi-Z cells visited)"),
            "rays": Num(4, 1, 256, integer=True, doc="GGX visible-normal rays per pixel at max_roughness, fewer below "
                                                     "it (roughness / max_roughness of them; a mirror: 1), before the "
                                                     "spatial resolve"),
            "ray_length": OneOf((Enum(("auto",)), Num(None, 0.0, lo_open=True)), default="auto",
                                doc="how far a ray is followed: auto = the scene's extent (as thickness's; 50 where "
                                    "only infinite planes bound it), as far as a ray inside the bounds can meet them, "
                                    "or scene units"),
            "seed": Num(1, 0, 2**31 - 1, integer=True, doc="random seed of the rays"),
            "defer_to_probes": Bool(True, doc="where a ray meets a reflection probe's own box or sphere (a wall, a "
                                              "floor), take the probe's path-traced capture of that point over the "
                                              "frame's, as far as the capture resolves the lobe (false: the frame "
                                              "wherever a ray hits; sharper where the frame's light is right)"),
        }),
        "reflection_probes": Bool(True, doc="prefiltered: read the scene's reflection probes where they reach "
                                            "(false: the distant panorama's chain alone)"),
        "ao": Enum(("off", "gtao", "raytraced"), "off",
                   doc="ambient occlusion of the IBL: gtao (screen-space horizons, Jimenez et al. 2016) or raytraced "
                       "(cosine-weighted rays within ao_radius through the BVH) multiplies the diffuse IBL, and "
                       "Lagarde's specular occlusion the specular IBL"),
        "ao_radius": Num(1.0, 0.0, lo_open=True, doc="ao: how far an occluder counts (scene units)"),
        "ao_samples": Num(16, 1, 4096, integer=True, doc="ao raytraced: rays per G-buffer sample (stratified, seeded)"),
        "ao_multibounce": Bool(False, doc="ao: Jimenez et al.'s multi-bounce fit in the albedo (brighter occlusion "
                                          "on light surfaces, the light interreflection brings back): closer to the "
                                          "converged reference on both scenes measured (diffuse with GTAO: sphere "
                                          "grid 11.5% against 17.4% without it, knot 42.9% against 52.8%, "
                                          "docs/manual.md); off by default, GTAO as Jimenez et al. publish it"),
        "gtao": Section(doc="ao gtao: the screen-space search (defaults tuned against raytraced AO: "
                            "benchmarks/tune_gtao.py)", fields={
            "slices": Num(GTAO_DEFAULTS["slices"], 1, 64, integer=True, doc="half-planes through the view vector per pixel"),
            "steps": Num(GTAO_DEFAULTS["steps"], 1, 64, integer=True, doc="depth samples per side of each slice"),
            "radius_scale": Num(GTAO_DEFAULTS["radius_scale"], 0.0, 16.0, lo_open=True,
                                doc="search radius over ao_radius (the screen sees only the front surfaces)"),
            "falloff": Num(GTAO_DEFAULTS["falloff"], 0.0, 1.0, lo_open=True,
                           doc="share of the radius over which an occluder's weight fades to 0"),
            "power": Num(GTAO_DEFAULTS["power"], 0.0, 16.0, lo_open=True, doc="exponent on the raw visibility"),
            "denoise": Num(GTAO_DEFAULTS["denoise"], 0, 8, integer=True,
                           doc="denoise radius in blocks (the mean over (2r+1)^2 blocks on the same surface; 0: none)"),
            "resolution": Enum(("half", "full"), GTAO_DEFAULTS["resolution"],
                               doc="search once per 2x2 block of pixels (half) or per pixel (full)"),
        }),
        "tonemap": Enum(("aces", "reinhard", "hable", "pbr_neutral", "linear"), "aces", doc="tone-mapping operator"),
        "exposure": Num(0.0, -32.0, 32.0, doc="exposure in EV (radiance x 2^EV before the operator)"),
        "output_transfer": Enum(("srgb", "gamma"), "srgb", doc="display encoding"),
        "gamma": Num(2.2, 0.0, 10.0, lo_open=True, doc="for output_transfer: gamma"),
    }),
    "sweep": Section(doc="what `iblbake sheet` varies: one or two axes of key paths (render ignores it)", fields={
        "title": Str(doc="the sheet's title (default: the scene file's name)"),
        "rows": Raw(doc="an axis: {key: KEY.PATH, values: [...]}, {key: KEY.PATH, range: {start, stop, count, "
                        "geometric}}, or {steps: [{KEY.PATH: value, ..., label: text}, ...]}"),
        "columns": Raw(doc="an axis, as rows"),
    }),
    "output": Section(doc="what is written (relative to the scene file; render overwrites its outputs)", fields={
        "frame": StrList(doc="frame path(s): .png (tone-mapped 8-bit), .exr (linear RGBA)"),
        "normal": Str(path=True, doc="AOV: world-space shading normal, EXR"),
        "albedo": Str(path=True, doc="AOV: base colour, EXR"),
        "depth": Str(path=True, doc="AOV: distance along the camera ray (0 where nothing is hit), EXR"),
        "object": Str(path=True, doc="AOV: the object (its index N in objects) each pixel's first sample hit, -1 where none, EXR"),
        "dither": Bool(False, doc="add +-0.5 LSB triangular dither before 8-bit quantisation"),
    }),
})


def schema_text() -> str:
    """The schema as an indented reference (render --help-schema)."""
    rows = []

    def field_line(indent, k, f):
        d = getattr(f, "default", None)
        dflt = "" if d is None else f" (default {d})"
        return f"{'  ' * indent}{k}: {f.describe()}{dflt} -- {f.doc}"

    def walk(spec, indent):
        if spec.required:
            rows.append(f"{'  ' * indent}# required: {', '.join(spec.required)}")
        if spec.exclusive:
            rows.append(f"{'  ' * indent}# exactly one of: {', '.join(spec.exclusive)}")
        for k, f in spec.fields.items():
            if isinstance(f, Section):
                rows.append(f"{'  ' * indent}{k}:  # {f.doc}")
                walk(f, indent + 1)
            elif isinstance(f, MapOf):
                rows.append(f"{'  ' * indent}{k}:  # {f.doc}")
                rows.append(f"{'  ' * (indent + 1)}NAME:  # {f.section.doc}")
                walk(f.section, indent + 2)
            elif isinstance(f, ListOf):
                rows.append(f"{'  ' * indent}{k}:  # {f.doc}; a list of:")
                rows.append(f"{'  ' * (indent + 1)}- # {f.section.doc}")
                walk(f.section, indent + 2)
            else:
                rows.append(field_line(indent, k, f))

    walk(SCHEMA, 0)
    return "\n".join(rows) + "\n"


def _md(text: str) -> str:
    return str(text).replace("|", "\\|")


def schema_markdown() -> str:
    """docs/scene.md: every key of the schema, one table per top-level section (the same table
    that --help-schema prints and the validator walks)."""
    out = ["# Scene files", "",
           "Generated from `iblbake/scene/schema.py` by `python -m iblbake.scene.schema > docs/scene.md`",
           "(`make docs`); `iblbake render --help-schema` prints the same table. A scene is YAML; every",
           "key below can also be set from the command line with `--set KEY.PATH=VALUE` (a YAML value),",
           "and relative paths are relative to the scene file. Errors name the file, the line and the",
           "dotted key, with the closest valid key for a typo.", ""]

    def notes(spec) -> str:
        n = []
        if spec.required:
            n.append(f"required: {', '.join(f'`{k}`' for k in spec.required)}")
        if spec.exclusive:
            n.append(f"exactly one of {', '.join(f'`{k}`' for k in spec.exclusive)}")
        return "; ".join(n)

    def row(key, kind, default, doc):
        d = "" if default is None else "`" + _md(default) + "`"
        return f"| `{key}` | {_md(kind)} | {d} | {doc} |"

    def rows(spec, prefix, table):
        for k, f in spec.fields.items():
            key = f"{prefix}.{k}" if prefix else k
            if isinstance(f, (Section, MapOf, ListOf)):
                sub = f if isinstance(f, Section) else f.section
                key = key + {Section: "", MapOf: ".NAME", ListOf: ".N"}[type(f)]
                kind = {Section: "section", MapOf: "named sections", ListOf: "list of sections"}[type(f)]
                doc = _md(f.doc if isinstance(f, Section) else f"{f.doc}: {f.section.doc}")
                table.append(row(key, kind, None, "; ".join(x for x in (doc, notes(sub)) if x)))
                rows(sub, key, table)
            else:
                table.append(row(key, f.describe(), getattr(f, "default", None), _md(f.doc)))

    out += [f"Required: {', '.join(f'`{k}`' for k in SCHEMA.required)}.", ""]
    for k, f in SCHEMA.fields.items():
        table = ["| key | type | default | meaning |", "|---|---|---|---|"]
        rows(Section(fields={k: f}), "", table)
        out += [f"## `{k}`", ""] + table + [""]
    return "\n".join(out)


if __name__ == "__main__":
    import sys
    sys.stdout.write(schema_markdown())
