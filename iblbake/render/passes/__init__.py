"""The render passes, in the order they run. Each is one module with its kernel file; plan()
asks every one whether the scene calls for it (iblbake/render/passes/base.py: the contract)."""

from iblbake.render.passes.ao import AmbientOcclusion
from iblbake.render.passes.background import Background
from iblbake.render.passes.gbuffer import GBuffer
from iblbake.render.passes.gtao import GroundTruthAO
from iblbake.render.passes.importance import Importance
from iblbake.render.passes.lights import Lights
from iblbake.render.passes.material import Materials
from iblbake.render.passes.reference import Reference
from iblbake.render.passes.resolve import Resolve
from iblbake.render.passes.shade import Shade
from iblbake.render.passes.ssr import ScreenSpaceReflections
from iblbake.render.passes.tonemap import Tonemap

PASSES = (GBuffer(), Materials(), AmbientOcclusion(), GroundTruthAO(), Importance(), Shade(), Reference(), Lights(),
          ScreenSpaceReflections(), Background(), Resolve(), Tonemap())
