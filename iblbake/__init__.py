"""iblbake: bake image-based lighting data and check what it looks like.

The public API is iblbake.api, re-exported here (docs/api.md): `import iblbake` loads only this
file and iblbake.errors; the API module and what it calls (numpy, OpenImageIO, pyopencl) load on
first use of a name, so a build script or the command line pays for what it calls."""

import sys as _sys

if _sys.argv[:1] == ["-m"]:
    # `python -m iblbake.cli`: runpy imports this package (in a fresh clone, compiling it) before
    # the entry point can say how Ctrl-C is handled, so its quiet exit (iblbake.entry) is set here
    # first, with the builtin _signal (the signal module's enums take a millisecond to import).
    # sys.argv[0] is "-m" exactly while the module is being located (the docs of -m): a library
    # import never takes this branch.
    import _signal

    _signal.signal(_signal.SIGINT, lambda signum, frame: (_sys.stderr.write("iblbake: interrupted\n"),
                                                          __import__("os")._exit(130)))

import types as _types

from iblbake.errors import DeviceError, Error, InputError, UsageError

__version__ = "0.1.0"

# what follows semantic versioning from 0.1.0: a name removed here is a major version
__all__ = [
    "Accuracy", "Basis", "Chain", "DeviceError", "Error", "Frame", "InputError", "Lightmap", "Panorama",
    "ProbeVolume", "Renderer", "SH", "Scene", "UsageError", "accuracy", "bake_lightmap", "bake_probes", "basis",
    "dfg", "load_panorama", "load_scene", "prefilter", "render", "sh",
]
_LAZY = frozenset(__all__) - {"DeviceError", "Error", "InputError", "UsageError"}


class _Package(_types.ModuleType):
    """The package's module type. Its public names load on first use (__getattr__: `import
    iblbake` does not load the API module or what it imports); dir() lists what __all__ does, not
    the package's machinery or the submodules loaded meanwhile; and the public function
    iblbake.render keeps its name though a subpackage shares it: the import system binds a
    subpackage on its parent once it loads, which would put the subpackage where the function is
    (code that wants the subpackage imports from it: `from iblbake.render import frame`). As
    methods here, not module functions, these stay out of help(iblbake)."""

    def __getattr__(self, name):
        if name in _LAZY:
            from iblbake import api
            value = getattr(api, name)
            self.__dict__[name] = value          # once: later lookups are plain attribute reads
            return value
        raise AttributeError(f"module 'iblbake' has no attribute {name!r}")

    def __dir__(self):
        return sorted(set(__all__) | {n for n in self.__dict__ if n.startswith("__")})

    def __setattr__(self, name, value):
        if name in _LAZY and isinstance(value, _types.ModuleType):
            return
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Package
