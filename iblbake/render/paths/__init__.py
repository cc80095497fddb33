"""The path tracer's host side: the Tracer of rays from points (tracer.py: the probes' and the
captures' ray source) and the reference's profile (profile.py: where its time goes). The kernels:
kernels/paths/paths.h (every vertex after the first), kernels/bsdf.h (the one BSDF), kernels/paths/reference.cl
(the camera's G-buffer samples) and kernels/paths/probe_trace.cl (rays from points); the launch policy:
iblbake/device/launch.py."""
