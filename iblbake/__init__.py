"""iblbake: bake image-based lighting data and check what it looks like."""

__version__ = "0.1.0"
