"""The lighting source contract: an approximate lighting term the shade pass (passes/shade.py,
kernels/shade.cl) composes. A source declares when it is on (runs), the kernel defines it adds,
the bakes it reads, the scene sections it reads beyond `effects`, the kernel parameters it binds
and their values (args: its own; placeholders: what the kernel reads, unused, where it is off),
and the buffers it needs; its kernel function lives in its header (kernels/<header>). Adding a
source touches its module here, its header and the dispatch lines of shade.cl."""

from __future__ import annotations


class Source:
    name = ""
    header = ""              # kernels/<header>: its kernel function
    params: tuple = ()       # the shade kernel's parameters it binds
    sections: tuple = ()     # the scene sections it reads beyond effects (the shade pass's reuse key)
    buffers: tuple = ()      # render.passes.base.Buffer declarations, allocated with the shade pass's

    def runs(self, scene, fx) -> bool:
        return False

    def defines(self, scene, fx) -> dict:
        return {}

    def reads_bakes(self, scene, fx) -> list:
        return []

    def args(self, ctx) -> dict:
        """Its parameters' values for this frame (it runs)."""
        return {}

    def placeholders(self, rt) -> dict:
        """Values for its parameters where it does not run (the kernel is compiled without it)."""
        return {}
