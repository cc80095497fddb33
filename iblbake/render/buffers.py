"""A frame buffer's declaration (render/passes/base.py: the pass contract; render/sources/: the
shade pass's sources declare theirs too)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

ELEMENT_BYTES = {"float4": 16, "float": 4, "uchar4": 4, "int": 4}


@dataclass(frozen=True)
class Buffer:
    """A device buffer of the frame, bound by `name` to every kernel parameter of that name:
    `count` elements of `dtype` per G-buffer sample of the tile (per="sample"), per pixel of the
    tile ("pixel"), or count(scene data) elements once per frame ("frame"). `when` names a define
    of the declaring pass without which the pass leaves the buffer alone, or "TILED" (needed only
    when the frame renders in several tiles). A buffer that no running pass needs is bound to a
    placeholder (the kernels compiled without its feature never touch it)."""
    name: str
    dtype: str = "float4"
    per: str = "sample"
    count: int | Callable = 1
    when: str | None = None

    def element_bytes(self, data: dict | None = None) -> int:
        """Bytes per sample, per pixel, or in all (per frame)."""
        n = self.count(data) if callable(self.count) else self.count
        return ELEMENT_BYTES[self.dtype] * n
