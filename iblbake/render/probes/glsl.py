"""probes.glsl (render/probes): a GLSL function that samples a volume's files as kernels/probes.h
does, the grid and settings baked in (a directional basis through its own GLSL, core/bases glsl)."""

from __future__ import annotations

import math

from iblbake.core.bases.probes import PROBE_BASES
from iblbake.render.probes.volume import basis_of
from iblbake.scene.layout import PROBE_VOLUME, PROBE_WEIGHTS


SH_GLSL = ("0.28209479177387814", "0.4886025119029199 * d.y", "0.4886025119029199 * d.z", "0.4886025119029199 * d.x",
           "1.0925484305920792 * d.x * d.y", "1.0925484305920792 * d.y * d.z",
           "0.31539156525252005 * (3.0 * d.z * d.z - 1.0)", "1.0925484305920792 * d.x * d.z",
           "0.5462742152960396 * (d.x * d.x - d.y * d.y)")     # sh.h's basis at l <= 2, term by term


def basis_glsl(name: str, opts: dict) -> tuple:
    """(functions, probeOwnIrradiance's lines, probeOwnSpecular's lines) of probe basis `name` with
    options `opts` (core/bases/probes.py glsl: a directional basis' own GLSL, one formula)."""
    return PROBE_BASES[name].glsl(opts)


SPECULAR_TABLES = tuple(b.specular_table for b in PROBE_BASES.values() if b.specular_table)   # beside the atlases
SPECULAR_HELP = """
// specular (the basis carries a lobe; effects.specular: probes) = (F0 A + F90 B) (the split sum's DFG
// table at n.v, roughness) * mix(skySpecular, probeSpecularRadiance(P, N, V, roughness), probeVolumeWeight(P)):
// each probe's radiance along the warped GGX lobe, blended by the irradiance's weights (linearly); the
// distant prefiltered chain takes over outside the volume."""


def record_constants(volume: dict) -> str:
    """The volume record (scene/layout.py PROBE_VOLUME) as GLSL constants PROBE_<NAME>."""
    rows = []
    for name, (_row, _lane, n, kind) in PROBE_VOLUME.items():
        values = [volume[name]] if n == 1 else list(volume[name])
        text = ", ".join(str(int(x)) if kind == "int" else f"{x:.9g}" for x in values)
        glsl_type = {"int": "int", "float": "float"}[kind] if n == 1 else ("ivec" if kind == "int" else "vec") + str(n)
        rows.append(f"const {glsl_type} PROBE_{name.upper()} = {text if n == 1 else f'{glsl_type}({text})'};")
    return "\n".join(rows)


def light_constants(lights: list) -> str:
    """The directional lights of probes.json's `lights` (files.light_entries) as GLSL constants: what
    an engine draws per pixel besides the probes (the panorama's extracted sun and lamps, which it
    cannot know of otherwise); point and spot lights are the scene's own, listed in probes.json."""
    sun = [lt for lt in lights if "directional" in lt]
    n = len(sun)
    head = (f"// + the {n} directional lights of probes.json's lights, drawn per pixel with their shadows (the probes\n"
            f"// hold their bounce, not their direct light): diffuse += albedo / PI * PROBE_LIGHT_IRRADIANCE[i] *\n"
            f"// max(dot(N, PROBE_LIGHT_TO[i]), 0.0) * shadow (a disk of PROBE_LIGHT_SIN_RADIUS[i], the sine of its\n"
            f"// angular radius); PROBE_LIGHT_TO: unit, world frame, towards the light (the arrays only where\n"
            f"// PROBE_LIGHT_COUNT > 0: guard a loop over them with #if)\n#define PROBE_LIGHT_COUNT {n}")
    if not n:
        return head

    def vec3s(rows):
        return ", ".join("vec3(" + ", ".join(f"{x:.9g}" for x in r) + ")" for r in rows)
    to = [[-x / math.sqrt(sum(y * y for y in lt["directional"]["direction"])) for x in lt["directional"]["direction"]]
          for lt in sun]
    sines = ", ".join(f"{math.sin(math.radians(lt['directional']['angular_diameter']) / 2):.9g}" for lt in sun)
    sources = "".join(f"\n// [{k}] {lt['source']}, shadows {lt['shadows']}" for k, lt in enumerate(sun))
    return (f"{head}{sources}\nconst vec3 PROBE_LIGHT_TO[{n}] = vec3[{n}]({vec3s(to)});\n"
            f"const vec3 PROBE_LIGHT_IRRADIANCE[{n}] = vec3[{n}]({vec3s(lt['irradiance'] for lt in sun)});\n"
            f"const float PROBE_LIGHT_SIN_RADIUS[{n}] = float[{n}]({sines});")


def sky_function(sky: dict | None) -> str:
    """probes.json's `sky` (files.sky_entry) as probeSkyIrradiance(n): the panorama the probes saw,
    less the lights extracted from it (those are PROBE_LIGHT_*: `iblbake sh` of the whole panorama
    would count them twice), in the world frame and the probes' units."""
    if not sky:
        return ""
    from iblbake.bake.sh import glsl_function
    said = "less the lights extracted from it (PROBE_LIGHT_*)" if sky["lights_extracted"] else "whole"
    return (f"// the sky's irradiance: probes.json's sky, {sky['bands']} SH bands (window {sky['window']}) of the "
            f"panorama the\n// probes saw, {said}; world frame, the probes' units\n"
            + glsl_function(sky["irradiance"], sky["bands"], "probeSkyIrradiance", "PROBE_SKY_SH",
                            "PROBE_SKY_SH_BANDS"))


def glsl(volume: dict, man: dict) -> str:
    """A GLSL function sampling the written files as kernels/probes.h does (the hardware's bilinear
    filter in place of its reads), the volume's grid and settings baked in."""
    w = {k: repr(v) for k, v in PROBE_WEIGHTS.items()}      # DDGI's weights, as the kernel's
    nx, ny, nz = volume["counts"]
    entry = basis_of(volume)
    flags = entry.defines(volume["settings"])             # kernels/probes.h's switches, the same here
    basis = "\n".join(f"    Y[{k}] = {e};" for k, e in enumerate(SH_GLSL))
    basis_src, own, spec = entry.glsl(volume["settings"])
    table = (f"\n//   {entry.glsl_table}  {entry.specular_table} (unfiltered: the specular functions read it "
             f"bilinearly)" if entry.specular_table else "")
    return f"""// iblbake irradiance probes: {nx} x {ny} x {nz}, {volume['representation']} irradiance, RTXGI-DDGI layout
// (probes.json holds the conventions). Bind the files as 2D float textures, each with its first
// (top) row at t = 0, clamped to the edge:
//   probeIrradianceAtlas  {man['files']['irradiance']} ({'linear' if entry.atlas else 'nearest'} filtering)
//   probeDistanceAtlas    distance.exr (linear filtering)
//   probeDataTexture      probe_data.exr (nearest){table}
// diffuse = albedo / PI * mix(probeSkyIrradiance(N), probeIrradiance(P, N, V), probeVolumeWeight(P)):
// world position, unit shading normal, unit vector towards the viewer; the sky's irradiance takes
// over outside the volume (and where probeBlend's w is 0).{SPECULAR_HELP if spec else ""}
{light_constants(man.get("lights", []))}
{sky_function(man.get("sky"))}
#define PROBES_SH {int("PROBES_SH" in flags)}
#define PROBES_BASIS {int("PROBES_BASIS" in flags)}
#define PROBES_SPECULAR {int(bool(spec))}
#define PROBE_VISIBILITY {int(volume['visibility'])}
#define PROBE_CLASSIFICATION {int(volume['classification'])}
{record_constants(volume)}

uniform sampler2D probeIrradianceAtlas;
uniform sampler2D probeDistanceAtlas;
uniform sampler2D probeDataTexture;
{basis_src}
vec2 probeOctahedral(vec3 d) {{
    vec2 uv = d.xy / (abs(d.x) + abs(d.y) + abs(d.z));
    if (d.z < 0.0) uv = (1.0 - abs(uv.yx)) * vec2(uv.x >= 0.0 ? 1.0 : -1.0, uv.y >= 0.0 ? 1.0 : -1.0);
    return uv;
}}

vec2 probeUV(int index, vec2 oct, int n) {{
    int tile = n + 2;
    int col = index % PROBE_COUNTS.x + (index / (PROBE_COUNTS.x * PROBE_COUNTS.z)) * PROBE_COUNTS.x;
    int row = (index / PROBE_COUNTS.x) % PROBE_COUNTS.z;
    vec2 texel = vec2(float(col * tile), float(row * tile)) + 0.5 * float(tile) + oct * (0.5 * float(n));
    return texel / vec2(float(tile * PROBE_COUNTS.x * PROBE_COUNTS.y), float(tile * PROBE_COUNTS.z));
}}

vec3 probeOwnIrradiance(int index, vec3 d) {{
#if PROBES_SH
    float Y[9];
{basis}
    vec3 e = vec3(0.0);
    for (int k = 0; k < 9; ++k) e += texelFetch(probeIrradianceAtlas, ivec2(k, index), 0).rgb * Y[k];
    return max(e, vec3(0.0));
#elif PROBES_BASIS
{own}
#else
    return max(textureLod(probeIrradianceAtlas, probeUV(index, probeOctahedral(d), PROBE_IRRADIANCE_TEXELS), 0.0).rgb,
               vec3(0.0));
#endif
}}

#if PROBES_SPECULAR
vec3 probeOwnSpecular(int index, vec3 n, vec3 v, float roughness) {{
{spec}
}}
#endif

float probeVolumeWeight(vec3 p) {{
    vec3 n = vec3(PROBE_COUNTS);
    vec3 halfExtent = 0.5 * PROBE_SPACING * n * vec3(notEqual(n, vec3(1.0)));   // the cells' box
    vec3 delta = abs(p - (PROBE_ORIGIN + 0.5 * PROBE_SPACING * (n - 1.0))) - halfExtent;
    vec3 w = 1.0 - clamp(delta / PROBE_SPACING, 0.0, 1.0);
    return w.x * w.y * w.z;
}}

// the index of the probe at grid coordinates c (kernels/probes.h probe_index), and its data texel: the
// offset in spacing units, the state in w
int probeIndex(ivec3 c) {{
    return c.y * PROBE_COUNTS.x * PROBE_COUNTS.z + c.z * PROBE_COUNTS.x + c.x;
}}

vec4 probeData(int index) {{
    int planeWidth = PROBE_COUNTS.x * PROBE_COUNTS.y;
    return texelFetch(probeDataTexture, ivec2(index % planeWidth, index / planeWidth), 0);
}}

// probe c's own weight at the biased point, its trilinear factor left out (DDGI's with visibility, 1
// without): 0 for an inactive probe; no value read (kernels/probes.h probe_weight)
float probeWeight(ivec3 c, vec3 p, vec3 biased, vec3 n) {{
    int index = probeIndex(c);
    vec4 data = probeData(index);
#if PROBE_CLASSIFICATION
    if (data.w != 0.0) return 0.0;
#endif
#if PROBE_VISIBILITY
    vec3 pp = PROBE_ORIGIN + vec3(c) * PROBE_SPACING + data.xyz * PROBE_SPACING;
    float wrap = 0.5 * (dot(normalize(pp - p), n) + 1.0);
    float w = wrap * wrap + {w['WRAP_FLOOR']};
    vec3 toProbe = pp - biased;
    float dist = length(toProbe);
    vec2 m = textureLod(probeDistanceAtlas, probeUV(index, probeOctahedral(-toProbe / dist), PROBE_DISTANCE_TEXELS),
                        0.0).rg;
    float cheb = 1.0;
    if (dist > m.x) {{
        float variance = abs(m.x * m.x - m.y), dv = dist - m.x;
        cheb = variance / (variance + dv * dv);
        cheb = cheb * cheb * cheb;
    }}
    w *= max({w['CHEBYSHEV_FLOOR']}, cheb);
    w = max(1e-6, w);
    if (w < {w['CRUSH']}) w *= w * w * (1.0 / ({w['CRUSH']} * {w['CRUSH']}));
    return w;
#else
    return 1.0;
#endif
}}

// probe c's weight given its own (probeWeight's w) and its factor falloff (trilinear, or the fallback's
// inverse square distance), and its value (probeOwnIrradiance, sqrt with visibility; or the specular
// radiance, as it is): 0 for an inactive probe (kernels/probes.h probe_weighted)
float probeWeighted(float w, ivec3 c, vec3 n, vec3 v, vec3 falloff, float roughness, bool specular, out vec3 value) {{
    value = vec3(0.0);
    if (w == 0.0) return 0.0;
    int index = probeIndex(c);
#if PROBES_SPECULAR
    vec3 e = specular ? probeOwnSpecular(index, n, v, roughness) : probeOwnIrradiance(index, n);
#else
    vec3 e = probeOwnIrradiance(index, n);
#endif
#if PROBE_VISIBILITY
    vec3 tri = max(falloff, vec3({w['TRILINEAR_FLOOR']}));
    value = specular ? e : sqrt(e);
    return w * tri.x * tri.y * tri.z;
#else
    value = e;
    return falloff.x * falloff.y * falloff.z;
#endif
}}

// the grid cell of g (a point in grid units) as kernels/probes.h probe_cell: its lowest probe, clamped
// to the grid, and g's trilinear fractions in it
ivec3 probeCell(vec3 g, ivec3 last, out vec3 alpha) {{
    ivec3 base = clamp(ivec3(floor(g)), ivec3(0), last);
    alpha = clamp(g - vec3(base), 0.0, 1.0);
    return base;
}}

// where probeBlend's value came from (its w), as kernels/probes.h PROBE_SOURCE_*
const float PROBE_SOURCE_NONE = 0.0, PROBE_SOURCE_CELL = 1.0, PROBE_SOURCE_NEAREST = 2.0;

// the probes around p blended as kernels/probes.h probe_blend_cell: the eight of the cell, or where all
// eight are off the active ones of the 4 x 4 x 4 around it by inverse square distance; the irradiance at n
// (sqrt-blended with visibility), or (specular) each probe's radiance along the warped GGX lobe, blended
// linearly; w the source, PROBE_SOURCE_NONE (0) where no active probe is near (the renderer takes the
// sky's light there: do so too). The cell's lowest probe in cell, its eight probes' own weights in own.
vec4 probeBlendCell(vec3 p, vec3 n, vec3 v, float roughness, bool specular, out ivec3 cell, out float own[8]) {{
    vec3 biased = p + n * PROBE_NORMAL_BIAS + v * PROBE_VIEW_BIAS;
    vec3 g = (biased - PROBE_ORIGIN) / PROBE_SPACING;
    ivec3 last = PROBE_COUNTS - 1;
    vec3 alpha;
    ivec3 base = probeCell(g, last, alpha);
    cell = base;
    vec3 sum = vec3(0.0), value;
    float wsum = 0.0, source = PROBE_SOURCE_CELL;
    for (int i = 0; i < 8; ++i) {{
        ivec3 off = ivec3(i & 1, (i >> 1) & 1, (i >> 2) & 1);
        ivec3 c = clamp(base + off, ivec3(0), last);
        own[i] = probeWeight(c, p, biased, n);
        float w = probeWeighted(own[i], c, n, v, mix(1.0 - alpha, alpha, vec3(off)), roughness, specular, value);
        sum += w * value;
        wsum += w;
    }}
    if (!(wsum > 0.0)) {{
        source = PROBE_SOURCE_NEAREST;
        ivec3 lo = max(base - 1, ivec3(0)), hi = min(base + 2, last);
        for (int z = lo.z; z <= hi.z; ++z)
            for (int y = lo.y; y <= hi.y; ++y)
                for (int x = lo.x; x <= hi.x; ++x) {{
                    vec3 dc = vec3(x, y, z) - g;
                    ivec3 c = ivec3(x, y, z);
                    float w = probeWeighted(probeWeight(c, p, biased, n), c, n, v,
                                            vec3(1.0 / max(dot(dc, dc), 0.01), 1.0, 1.0), roughness, specular, value);
                    sum += w * value;
                    wsum += w;
                }}
    }}
    if (!(wsum > 0.0)) return vec4(0.0, 0.0, 0.0, PROBE_SOURCE_NONE);
    vec3 s = sum / wsum;
#if PROBE_VISIBILITY
    if (!specular) return vec4(s * s, source);
#endif
    return vec4(s, source);
}}

vec4 probeBlend(vec3 p, vec3 n, vec3 v, float roughness, bool specular) {{
    ivec3 cell;
    float own[8];
    return probeBlendCell(p, n, v, roughness, specular, cell, own);
}}

// the probes' weight on either side of the (unbiased) cell of p along each axis, the axis' own trilinear factor
// left out (side0 the low sides', side1 the high), and each side's weighted offset along the axis in cells
// (shift0, shift1: divided by the side's weight, where the relocated layer stands), as kernels/probes.h
// probe_sides: own weights only (probeWeight); with `reuse`, a probe of the blend's cell `blended` weighs as it
// did there (own)
ivec3 probeSides(vec3 p, vec3 n, vec3 v, bool reuse, ivec3 blended, float own[8], out vec3 side0, out vec3 side1,
                 out vec3 shift0, out vec3 shift1, out vec3 alpha) {{
    vec3 biased = p + n * PROBE_NORMAL_BIAS + v * PROBE_VIEW_BIAS;
    ivec3 last = PROBE_COUNTS - 1;
    ivec3 base = probeCell((p - PROBE_ORIGIN) / PROBE_SPACING, last, alpha);
    side0 = vec3(0.0); side1 = vec3(0.0); shift0 = vec3(0.0); shift1 = vec3(0.0);
    for (int i = 0; i < 8; ++i) {{
        ivec3 off = ivec3(i & 1, (i >> 1) & 1, (i >> 2) & 1), c = clamp(base + off, ivec3(0), last), d = c - blended;
        float w = reuse && all(greaterThanEqual(d, ivec3(0))) && all(lessThanEqual(d, ivec3(1)))
                  ? own[d.x + 2 * d.y + 4 * d.z] : probeWeight(c, p, biased, n);
        vec3 f = mix(1.0 - alpha, alpha, vec3(off));
#if PROBE_VISIBILITY
        f = max(f, vec3({w['TRILINEAR_FLOOR']}));
#endif
        vec3 o = probeData(probeIndex(c)).xyz;
        vec3 share = w * vec3(f.y * f.z, f.x * f.z, f.x * f.y);
        side0 += share * (1.0 - vec3(off));
        side1 += share * vec3(off);
        shift0 += share * o * (1.0 - vec3(off));
        shift1 += share * o * vec3(off);
    }}
    return base;
}}

// which side of axis k carries under NEAR_DEAD of the weight (a wall's): 0 the low, 1 the high, -1 neither
int probeDeadSide(vec3 side0, vec3 side1, int k) {{
    float total = side0[k] + side1[k];
    if (!(total > 0.0)) return -1;
    return side0[k] < {w['NEAR_DEAD']} * total ? 0 : side1[k] < {w['NEAR_DEAD']} * total ? 1 : -1;
}}

// the irradiance at p (0 where no active probe is near: probeBlend's w says so), stepped from the layer
// nearest a wall to the point as kernels/probes.h probe_irradiance (docs/conventions.md "Junctions"):
// along an axis where one side of the point's own cell carries under NEAR_DEAD of the weight, the read goes on
// linearly from the live layer where its probes stand, by the read one cell further in, where two axes or three
// have such a side, or one and the cell one further along another (towards the nearer layer) has one on that
// axis (within a cell of a junction); the steps only darken. Only a read of the cell's eight probes steps (not
// the nearest probes' stand-in), and only by such a read.
vec3 probeIrradiance(vec3 p, vec3 n, vec3 v) {{
    ivec3 blended;
    float own[8];
    vec4 e = probeBlendCell(p, n, v, 0.0, false, blended, own);
    if (e.w != PROBE_SOURCE_CELL) return e.xyz;
#if !PROBE_VISIBILITY && !PROBE_CLASSIFICATION
    return e.xyz;                                                   // every probe weighs 1: no side is light
#else
    ivec3 last = PROBE_COUNTS - 1;
    vec3 alpha;
    ivec3 base = probeCell((p - PROBE_ORIGIN) / PROBE_SPACING, last, alpha);
    int open = 0;                                                   // axes a step could be taken along
    for (int k = 0; k < 3; ++k)
        if (last[k] >= 2 && ((alpha[k] > 1e-6 && base[k] >= 1) || (1.0 - alpha[k] > 1e-6 && base[k] + 2 <= last[k])))
            ++open;
    if (open == 0) return e.xyz;
    vec3 side0, side1, shift0, shift1, near0, near1, nshift0, nshift1, nalpha;
    probeSides(p, n, v, true, blended, own, side0, side1, shift0, shift1, alpha);
    int walls = 0;
    for (int k = 0; k < 3; ++k) if (probeDeadSide(side0, side1, k) >= 0) ++walls;
    for (int k = 0; k < 3 && walls == 1; ++k) {{
        if (probeDeadSide(side0, side1, k) >= 0) continue;
        vec3 q = p;                                                 // one cell on, towards the nearer layer
        q[k] += (alpha[k] < 0.5 ? -1.0 : 1.0) * PROBE_SPACING[k];
        probeSides(q, n, v, false, blended, own, near0, near1, nshift0, nshift1, nalpha);
        if (probeDeadSide(near0, near1, k) >= 0) ++walls;
    }}
    if (walls < 2) return e.xyz;                                    // by a junction only
    vec3 step = vec3(0.0);
    for (int k = 0; k < 3; ++k) {{
        int dead = probeDeadSide(side0, side1, k);
        if (dead < 0) continue;
        float t = dead == 1 ? alpha[k] : 1.0 - alpha[k];              // cells from the point to the live layer
        int next = dead == 1 ? base[k] - 1 : base[k] + 2;              // the layer after it, inwards
        if (last[k] < 2 || !(t > 1e-6) || next < 0 || next > last[k]) continue;
        float o = dead == 1 ? -shift0[k] / side0[k] : shift1[k] / side1[k];   // the live layer o cells further in
        vec3 q = p;
        q[k] += (dead == 1 ? -1.0 : 1.0) * (t + 1.0) * PROBE_SPACING[k];
        vec4 e2 = probeBlend(q, n, v, 0.0, false);
        float reach = min(max(t + o, 0.0) / max(1.0 - o, 0.25), {w['STEP_REACH']});
        if (e2.w == PROBE_SOURCE_CELL) step -= reach * (e2.xyz - e.xyz);
    }}
    return clamp(e.xyz + step, {w['STEP_FLOOR']} * e.xyz, e.xyz);
#endif
}}

#if PROBES_SPECULAR
vec3 probeSpecularRadiance(vec3 p, vec3 n, vec3 v, float roughness) {{
    return probeBlend(p, n, v, roughness, true).xyz;
}}
#endif
"""
