"""numpy twin of the render kernels, float64, for tests on small frames: one module per kernel
it mirrors, re-exported here.

gbuffer      primary() (the G-buffer by brute force), occluded(), textures(), gbuffer_coords()
material     resolve_materials()
surface      surface(), diffuse_weight(), facing_normal(), to_env()
shade        shade(): SH or probe diffuse, importance-sampled, prefiltered and lobe specular, emission
probes       irradiance(), volume_weight(): the irradiance probes' sampling (kernels/probes.h)
reflection_probes  weight(), direction(), blend(): local reflection probes (kernels/reflection_probes.h)
ao, gtao     ambient_occlusion(); gtao(), gtao_denoise()
lights       lights(): analytic lights with hard and soft shadows, and their exact integral
reference    exact(): the integral the `reference` pass estimates (bounces 1), by quadrature
paths        radiance(): the reference with paths, sample for sample (bounces > 1)
"""

from iblbake.render.twin.gbuffer import occluded, ray_offset, primary, textures, hit_texcoords, map_uv, gbuffer_coords  # noqa: F401
from iblbake.render.twin.material import resolve_materials  # noqa: F401
from iblbake.render.twin.surface import facing_normal, to_env, surface, material_occlusion, diffuse_weight  # noqa: F401
from iblbake.render.twin.shade import shade, specular_occlusion, ao_multibounce, lobe  # noqa: F401
from iblbake.render.twin.gtao import gtao_noise, acos_fast, gtao, gtao_denoise  # noqa: F401
from iblbake.render.twin.ao import ambient_occlusion  # noqa: F401
from iblbake.render.twin.lights import representative_point, disk_specular, light_brdf_cos, lights  # noqa: F401
from iblbake.render.twin.reference import exact  # noqa: F401
from iblbake.render.twin.paths import radiance as path_radiance  # noqa: F401
