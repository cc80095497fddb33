"""The lighting sources the shade pass composes (render/sources/base.py: the contract), in the
order shade.cl adds them."""

from iblbake.render.sources.basis import BasisSpecular, DirectionalBasis
from iblbake.render.sources.importance import ImportanceSampled
from iblbake.render.sources.lightmap import Lightmap, LightmapSpecular
from iblbake.render.sources.lobe import Lobe
from iblbake.render.sources.prefiltered import SplitSum
from iblbake.render.sources.probes import IrradianceProbes, ProbeSpecular
from iblbake.render.sources.reflection_probes import ReflectionProbes
from iblbake.render.sources.sh import SphericalHarmonics
from iblbake.render.sources.ssr import ScreenSpaceSplit

SOURCES = (SphericalHarmonics(), DirectionalBasis(), IrradianceProbes(), Lightmap(), ImportanceSampled(), SplitSum(),
           Lobe(), BasisSpecular(), ProbeSpecular(), LightmapSpecular(),
           ReflectionProbes(),
           ScreenSpaceSplit())
