"""The path tracer's host side: one driver, trace(source, engine) (trace.py), over every ray source:
the camera's samples of the reference pass (camera.py), rays from points and rays per texel
(rays.py: the irradiance probes' rays, the reflection captures' texels), bound to their kernel by
the Tracer (tracer.py); and the reference's profile (profile.py: where its time goes). The kernels:
kernels/paths/paths.h (every vertex after the first), kernels/bsdf.h (the one BSDF),
kernels/paths/reference.cl (the camera's G-buffer samples) and kernels/paths/probe_trace.cl (rays from
points); the launch policy: iblbake/device/launch.py."""
