"""What an irradiance probe can store (the scene's `probes.irradiance`), registered once: DDGI's
octahedral irradiance atlas, L2 SH irradiance, and every directional basis of BASES that fits from
a probe's rays (project_rays). Each entry owns its file, its device packing, its kernel defines
(kernels/probes.h), its part of probes.glsl and of probes.json, and how its file is read back and
checked; the schema's choices, render/probes (bake, files, GLSL), the render sources, the twin and
the CLI derive from PROBE_BASES and never compare the name. The octahedral atlas' fit and reads are
the volume's own (render/probes/project.py, render/twin/probes.py): its entry says `atlas`.
Conventions: docs/conventions.md "Irradiance probes" and "Directional bases"."""

from __future__ import annotations

import numpy as np

from iblbake.core import sh as core_sh
from iblbake.core.bases import BASES

IRRADIANCE_UNITS = "irradiance E (W m^-2 for radiance in W m^-2 sr^-1), linear, float32; diffuse = albedo / pi * E"
RADIANCE_UNITS = ("radiance coefficients of the basis (W m^-2 sr^-1 in radiance units), linear, float32; its "
                  "irradiance function gives E, diffuse = albedo / pi * E")


class ProbeBasis:
    """A probe basis: what every entry answers (the defaults are the coefficient bases': one row of
    `floats` RGB coefficients a probe in its file, nearest filtering)."""
    name: str
    title: str
    file: str
    atlas = False            # an octahedral atlas of (texels + 2)^2 tiles (render/probes/project.py)
    directional = False      # a basis of BASES, evaluated by its kernels/bases.h header (one a frame)
    specular = False         # carries a specular lobe: `effects.specular: probes`
    lightmap = True          # a lightmap texel may hold it (scene/schema.py LIGHTMAP_BASES): its reading of a
                             # hemisphere's light (black below) at the normal is that light's irradiance
    specular_table = None    # the file of the table its GLSL specular reads, beside the atlases
    glsl_table = None        # ... and its sampler's name there
    units = RADIANCE_UNITS
    option_specs: dict = {}  # its options in a probes section: key -> (choices, default, doc), as BASES' OPTIONS
    doc: str                 # what it is, for the schema's probes.irradiance

    def variants(self) -> list:
        """Its options' variants a study compares (study/ladder.py probe_bases)."""
        return [{}]

    def label(self, opts: dict) -> str:
        return self.title

    def options(self, settings: dict) -> dict:
        """Its options from a probes section (the keys of the effects' names: probes.sg_lobes)."""
        return {}

    def floats(self, opts: dict) -> int:
        """Coefficients a probe stores, per channel."""
        raise NotImplementedError

    def stored_bytes(self, settings: dict, bytes_per_float: int) -> int:
        """Bytes an engine stores a probe's irradiance in (the study's cost column)."""
        return self.floats(self.options(settings)) * 3 * bytes_per_float

    def device_floats(self, settings: dict) -> int:
        """float4 rows a probe's irradiance takes on the device (grid.probe_bytes, said up front)."""
        return 16

    def shape(self, grid, settings: dict) -> tuple:
        """(rows, columns, channels) of its file."""
        return (grid.count, self.floats(self.options(settings)), 3)

    def check(self, irr, opts: dict) -> str | None:
        """What is wrong with a file's values read back, or None."""
        return None

    def defines(self, settings: dict) -> dict:
        """kernels/probes.h's switches selecting it."""
        return {}

    def pack(self, irr, opts: dict) -> np.ndarray:
        """Its file's values as the kernel's float4 rows."""
        irr = np.asarray(irr, np.float32)
        return np.pad(irr, [(0, 0)] * (irr.ndim - 1) + [(0, 1)]).reshape(-1, 4)

    def glsl(self, settings: dict) -> tuple:
        """(functions, probeOwnIrradiance's lines, probeOwnSpecular's lines) it adds to probes.glsl
        (render/probes/glsl.py): none but a directional basis'."""
        return "", "", ""

    def manifest(self, volume: dict) -> dict:
        """Its block of probes.json, beside the volume's own keys."""
        return {}

    def project_rays(self, lit, front, blends, dirs, opts: dict):
        """Each probe's coefficients (probes, floats, 3) from its rays' radiance lit (probes, rays, 3),
        back faces black (front: 1 where a ray met a front face or nothing), dirs (rays, 3) or each
        probe's own (probes, rays, 3) (a lightmap's texels); 0 for a probe that blends none (blends
        False)."""
        raise NotImplementedError

    def irradiance_at(self, irr, index, normals, opts: dict) -> np.ndarray:
        """The twin's irradiance (m, 3) of probes index (m,) of the file's values irr at normals
        (m, 3), float64 (before the clamp at 0)."""
        raise NotImplementedError

    def irradiance_columns(self, normals, opts: dict):
        """The irradiance (..., floats) at normals (..., 3) of each unit coefficient where the
        reading is linear in the coefficients (before its clamp at 0), else None: what a fit of
        the irradiance over chosen normals solves with (a lightmap texel's hemisphere)."""
        return None


class Octahedral(ProbeBasis):
    """DDGI's octahedral irradiance: a tile of n x n texels (probes.irradiance_texels) with RTXGI's
    1-texel border per probe, in RTXGI's atlas, read bilinearly."""
    name, title, file = "octahedral", "octahedral", "irradiance.exr"
    atlas = True
    lightmap = False         # a tile of texels a texel
    units = IRRADIANCE_UNITS
    doc = "DDGI's octahedral irradiance map"

    def device_floats(self, settings):
        return (settings["irradiance_texels"] + 2) ** 2

    def stored_bytes(self, settings, bytes_per_float):
        return settings["irradiance_texels"] ** 2 * 3 * bytes_per_float

    def shape(self, grid, settings):
        n, (nx, ny, nz) = settings["irradiance_texels"], grid.counts
        return ((n + 2) * nz, (n + 2) * nx * ny, 3)

    def check(self, irr, opts):
        return "holds negative irradiance" if (np.asarray(irr) < 0).any() else None


class SphericalHarmonics(ProbeBasis):
    """L2 SH irradiance: 9 RGB coefficients a probe (the rays' least-squares fit, convolved with the
    clamped cosine), sh.h's basis."""
    name, title, file = "sh", "SH L2", "irradiance_sh.exr"
    units = IRRADIANCE_UNITS
    doc = "L2 SH irradiance (9 RGB coefficients, least squares over its rays)"

    def floats(self, opts):
        return 9

    def defines(self, settings):
        return {"PROBES_SH": 1}

    def project_rays(self, lit, front, blends, dirs, opts):
        """The least-squares L2 fit of the front rays' radiance (a field in the span, a uniform sky,
        is exact), convolved with the clamped cosine."""
        y = core_sh.sh_basis(dirs, 3)               # (rays, 9), or each probe's own (probes, rays, 9)
        per = "p" if y.ndim == 3 else ""
        a = np.einsum(f"pr,{per}rk,{per}rj->pkj", front, y, y, optimize=True)
        b = np.einsum(f"prc,{per}rk->pkc", lit, y, optimize=True)
        a[~blends] = np.eye(9)
        coeffs = np.linalg.solve(a, b) * core_sh.ahat(3)[None, :, None]
        return np.where(blends[:, None, None], coeffs, 0.0)

    def irradiance_at(self, irr, index, normals, opts):
        return np.einsum("...k,...kc->...c", core_sh.sh_basis(normals, 3), irr[index])

    def irradiance_columns(self, normals, opts):
        return core_sh.sh_basis(normals, 3)


class Directional(ProbeBasis):
    """A directional basis of BASES (core/bases/NAME.py) stored per probe: its radiance coefficients
    in its own layout, packed by its module, evaluated by its header and its GLSL."""

    directional = True

    def __init__(self, module):
        self.m = module
        self.name, self.title, self.file = module.NAME, module.TITLE, f"basis_{module.NAME}.exr"
        self.specular = bool(getattr(module, "SPECULAR", False))
        self.lightmap = bool(getattr(module, "LIGHTMAP", True))
        self.specular_table = f"{module.NAME}_specular.exr" if hasattr(module, "specular_table") else None
        self.glsl_table = getattr(module, "GLSL_TABLE", None)
        self.option_specs = module.OPTIONS
        self.doc = f"{module.TITLE}, a directional basis fitted to its rays"

    def variants(self):
        return self.m.variants()

    def label(self, opts):
        return self.m.label(opts)

    def options(self, settings):
        return {k: settings.get(k, default) for k, (_choices, default, _doc) in self.option_specs.items()}

    def floats(self, opts):
        return self.m.floats(opts)

    def stored_bytes(self, settings, bytes_per_float):
        from iblbake.core import bases
        return bases.probe_bytes(self.name, self.options(settings), bytes_per_float)

    def specular_weights(self, r, lam_w, settings):
        """The warped lobe's weights s_k (core/bases specular_weights) with its options."""
        return self.m.specular_weights(r, lam_w, self.options(settings))
    def check(self, irr, opts):
        try:                          # every probe's coefficients as one basis's columns
            self.m.validate(np.asarray(irr).transpose(1, 0, 2).reshape(irr.shape[1], -1), opts)
        except ValueError as e:
            return str(e)
        return None

    def rows(self, opts) -> int:
        """float4 rows a probe's block takes (kernels/probes.h PROBE_BASIS_ROWS)."""
        return len(self.m.pack(np.zeros((self.m.floats(opts), 3)), opts))

    def defines(self, settings):
        opts = self.options(settings)
        return {**self.m.defines(opts), "PROBES_BASIS": 1, "BASIS_SPACE": "__global", "PROBE_BASIS_ROWS": self.rows(opts)}

    def pack(self, irr, opts):
        return np.stack([self.m.pack(c, opts) for c in np.asarray(irr, np.float32)]).reshape(-1, 4)

    def functions(self, settings, owner: str = "the probe's coefficients (probeOwnIrradiance)") -> str:
        """The basis's own GLSL functions (its module's glsl) with its coefficient array a variable
        instead of a constant (filled by its reader: `owner` says which), for probes.glsl and the
        lightmaps' GLSL (render/lightmaps/export.py)."""
        import re
        m, opts = self.m, self.options(settings)
        k = m.floats(opts)
        src, found = re.subn(rf"const vec3 {m.GLSL_COEFFS}\[{k}\] = vec3\[{k}\]\(.*?\n\);",
                             f"vec3 {m.GLSL_COEFFS}[{k}];     // {owner}", m.glsl(np.zeros((k, 3)), opts), flags=re.S)
        assert found == 1, self.name
        return src

    def glsl(self, settings):
        """The basis's functions (functions()), the lines that fill its coefficients from the probe's
        row of the file and call its irradiance function, the same calling its specular one where
        it carries a lobe."""
        m, opts = self.m, self.options(settings)
        k = m.floats(opts)
        src = self.functions(settings)
        fill = (f"    for (int k = 0; k < {k}; ++k) {m.GLSL_COEFFS}[k] = texelFetch(probeIrradianceAtlas, "
                f"ivec2(k, index), 0).rgb;\n")
        return src, fill + f"    return {m.GLSL_IRRADIANCE}(d);", \
            fill + f"    return {m.GLSL_SPECULAR}(n, v, roughness);" if self.specular else ""

    def table_image(self) -> np.ndarray:
        """The specular table its GLSL reads (float32, one channel), written as specular_table."""
        return self.m.specular_table({}).astype("float32")

    def manifest(self, volume):
        """What the basis's file holds: the basis, its options and its layout (the module's)."""
        opts = self.options(volume["settings"])
        return {"basis": {
            "name": self.name, "title": self.title, "options": opts, "floats": self.m.floats(opts),
            "layout": f"{self.file}: row = probe index, column k = the basis's coefficient k (RGB radiance "
                      f"coefficients, world frame; back-face rays black); the basis's own layout, its rows being "
                      f"the columns here: " + " ".join(self.m.__doc__.split("Layout:")[1].split()),
            "irradiance": "docs/conventions.md 'Directional bases'; probes.glsl's probeOwnIrradiance evaluates it"}}

    def project_rays(self, lit, front, blends, dirs, opts):
        """The basis's own fit on the rays (an equal-area set: moments 4 pi / N sum L B)."""
        return np.where(blends[:, None, None], self.m.project_rays(lit, dirs, opts), 0.0)

    def irradiance_columns(self, normals, opts):
        """Where the module's irradiance is linear (LINEAR): max(0, x) - max(0, -x) = x, so the
        unit coefficients' readings and their negatives' give each column before the clamp."""
        if not getattr(self.m, "LINEAR", False):
            return None
        eye = np.eye(self.m.floats(opts))
        return self.m.irradiance(eye, normals, opts) - self.m.irradiance(-eye, normals, opts)

    def irradiance_at(self, irr, index, normals, opts):
        """The basis's own float64 irradiance, probe by probe."""
        index = np.asarray(index)
        e = np.zeros(index.shape + (3,))
        for i in np.unique(index):
            sel = index == i
            e[sel] = self.m.irradiance(irr[i], normals[sel], opts)
        return e


PROBE_BASES = {b.name: b for b in (Octahedral(), SphericalHarmonics(),
                                   *(Directional(m) for m in BASES.values() if m.HEADER and hasattr(m, "project_rays")))}

