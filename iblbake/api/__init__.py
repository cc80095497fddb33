"""iblbake's public API (docs/api.md): bake image-based lighting from Python and get numpy arrays.

Every function returns arrays or the small dataclasses of its modules, prints nothing and raises
iblbake.Error subclasses (iblbake.errors) with one-line messages (the command line prints them);
warnings are returned (a `warnings` list) or passed to a `warn(message)` callback. The command
line (iblbake.cli) is a layer over this package: what a command bakes, this package bakes.

Conventions (docs/conventions.md): world right-handed, +y up; panoramas equirectangular
(u = 0.5 - atan2(x, z) / (2 pi), v = acos(y) / pi, row 0 at the top), linear RGB, radiance in
the file's units (W m^-2 sr^-1 for a physical one); roughness is perceptual (alpha = r^2).

Imports are lazy (numpy, OpenImageIO and pyopencl load inside the functions): `import iblbake`
stays cheap and each call pays for what it uses.

Arguments are checked before any work: a wrong kind or value is an InputError naming the argument
and what it takes. Messages call the arguments by their names here; the functions the command
line calls take `names`, a mapping of argument names to what its messages call them (its flags).

The modules by concept, each importing only those above it: guards (the argument checks),
runtimes (one OpenCL runtime per device), panorama, bakes (sh, prefilter, dfg), bases (the
directional bases), scenes (load_scene, render, Renderer), probes (bake_probes), lightmaps
(bake_lightmap), study (accuracy).
"""

from iblbake.api.bakes import SH, Chain, dfg, prefilter, sh
from iblbake.api.bases import Basis, basis
from iblbake.api.lightmaps import Lightmap, bake_lightmap
from iblbake.api.panorama import Panorama, load_panorama
from iblbake.api.probes import ProbeVolume, bake_probes
from iblbake.api.scenes import Renderer, load_scene, render
from iblbake.api.study import Accuracy, accuracy

__all__ = ["Accuracy", "Basis", "Chain", "Frame", "Lightmap", "Panorama", "ProbeVolume", "Renderer", "SH", "Scene",
           "accuracy", "bake_lightmap", "bake_probes", "basis", "dfg", "load_panorama", "load_scene", "prefilter",
           "render", "sh"]

# each public name says it is iblbake.api's (help(), reprs and pickles name it so, as before the
# modules were split): where it is defined is internal and moves with refactors
for _public in (SH, Chain, dfg, prefilter, sh, Basis, basis, Lightmap, bake_lightmap, Panorama, load_panorama,
                ProbeVolume, bake_probes, Renderer, load_scene, render, Accuracy, accuracy):
    _public.__module__ = __name__
del _public


def __getattr__(name):
    # the scene and frame classes live with their loader and renderer (iblbake.scene.load,
    # iblbake.render.frame), which import the schema, YAML and numpy: loaded when asked for
    if name == "Scene":
        from iblbake.scene.load import Scene
        return Scene
    if name == "Frame":
        from iblbake.render.frame import Frame
        return Frame
    raise AttributeError(f"module 'iblbake.api' has no attribute {name!r}")
