"""Scenes and frames: load a scene, render it once or across calls with a Renderer."""

from __future__ import annotations

from typing import TYPE_CHECKING

from iblbake.api.guards import (_arguments, _cache, _callback, _device, _flag, _is_path, _kind, _name, _names,
                                _no_nul, _overrides, _path, _shown)
from iblbake.api.runtimes import _on_device, _runtime
from iblbake.errors import InputError

if TYPE_CHECKING:                 # loaded on first use (import iblbake stays light)
    from iblbake.render.frame import Frame


@_arguments
def load_scene(path_or_dict, overrides=(), *, folder=".", outputs=None, names: dict | None = None):
    """A validated scene (iblbake.Scene: .data, the scene with every default filled and every path
    absolute; `iblbake render --help-schema` lists the keys).

    path_or_dict: a scene YAML file, a mapping of what one holds (its relative paths resolve in
        `folder`; numpy numbers and arrays, tuples and path objects read as the numbers, lists and
        strings a file holds), or a Scene (validated again with the overrides and outputs given).
        A Scene is read-only: one whose data was edited after loading is an InputError naming
        the key edited (here, and so in render, bake_probes and accuracy).
    overrides: 'key.path=value' strings applied before validation (values parse as YAML), as
        `iblbake render --set`: a list of them, or one string.
    outputs: frame paths that replace output.frame (as `render -o`): a list, or one path.
    names: what error messages call each argument (by default its name; the command line passes
        its flags).

    Raises InputError naming the file, line and dotted key (the closest valid key for a typo).
    """
    import os
    from collections.abc import Mapping

    from iblbake.scene import load as scene_load

    _names(names)
    overrides = _overrides(overrides)
    if outputs is not None:
        if _is_path(outputs):
            outputs = [outputs]
        if not (isinstance(outputs, (list, tuple)) and all(_is_path(o) for o in outputs)):
            raise InputError(f"outputs: give frame paths (.png or .exr; one, or a list of them), not {_shown(outputs)}")
        outputs = [os.fspath(_no_nul("outputs", o)) for o in outputs]
    said = _name(names, "overrides")
    if isinstance(path_or_dict, scene_load.Scene):
        edited = scene_load.edited_key(path_or_dict)
        if edited is not None:
            key = edited or "KEY"
            raise InputError(f"{path_or_dict.source}: Scene.data{'.' + edited if edited else ''} was changed after "
                             f"load_scene; a Scene is read-only: give the change as an override "
                             f"(iblbake.load_scene(scene, ['{key}=VALUE'])), or edit the mapping and load it again")
        if not overrides and outputs is None:
            return path_or_dict
        return scene_load.load_any(path_or_dict, overrides, outputs, override_name=said)
    if isinstance(path_or_dict, Mapping):
        _path("folder", folder, "a folder's")
        # the mapping itself, not a copy: a section holding the scene then names itself (materials.m.self)
        return scene_load.load_data(path_or_dict, folder, overrides, outputs, override_name=said)
    if not _is_path(path_or_dict):
        raise InputError(f"scene: give a scene file's path, a mapping of what one holds, or an iblbake.Scene, "
                         f"not {_kind(path_or_dict)}")
    return scene_load.load(_no_nul("scene", path_or_dict), overrides, outputs, override_name=said)


class Renderer:
    """Renders scenes on one OpenCL runtime and one bake cache, across calls: kernels are built
    once, bakes (SH, chains, DFG, probes) are kept in memory and in the cache folder, and with
    `reuse` passes whose inputs did not change since the last frame are not run again.

    device: an OpenCL device spec (default $IBLBAKE_DEVICE, else the first working GPU, else
        CPU). cache: the bake cache folder (default $IBLBAKE_CACHE, else the per-user cache).
    reuse: keep the last frame on the device for the next (a series of frames of one size).
    names: what error messages call each argument (by default its name; the command line passes
        its flags).
    """

    @_arguments
    def __init__(self, device: str | None = None, cache=None, reuse: bool = True, *, names: dict | None = None):
        from iblbake.render import Bakes, Reuse

        _device(device)
        cache = _cache(cache)
        reuse = _flag("reuse", reuse)
        self._names = _names(names)
        self.runtime = _runtime(device, names)
        self.bakes = Bakes(cache)
        self.bakes.runtime = self.runtime
        self._reuse = Reuse() if reuse else None

    @property
    def device(self) -> str:
        return self.runtime.device_label

    @_arguments
    def render(self, scene, *, warn=None, progress=None, profile_paths: bool = False) -> Frame:
        """Render a Scene (load_scene) into a Frame (iblbake.Frame: hdr, tonemapped, aovs,
        report). warn(message) gets the warnings, and the notes on what the scene asks that the
        frame does not do (a key not read, a term skipped); progress(fraction) the share of long
        work (path tracing, probe rays) done. profile_paths: after the frame, measure where the
        reference pass's time goes (per bounce: shading, closest-hit and shadow-ray traversal),
        the report's `paths_profile`; the frame is the same."""
        from iblbake.render import frame as render_frame

        _callback("warn", warn)
        _callback("progress", progress)
        profile_paths = _flag(_name(self._names, "profile_paths"), profile_paths)
        from iblbake.render.plan import effect_modes

        sc = load_scene(scene, names=self._names)
        if profile_paths:
            _profiled(sc, self._names)
        with _on_device(self.runtime):          # one frame at a time on the runtime (and this Renderer)
            frame = render_frame.render(sc, runtime=self.runtime, cache=self.bakes, reuse=self._reuse, warn=warn,
                                        progress=progress, profile_paths=profile_paths)
        for note in effect_modes(sc).notes:     # what the scene asks that the frame did not do
            if warn:
                warn(note)
        return frame


def _profiled(scene, names) -> None:
    """A scene asked to profile its paths has the reference pass, or fails in one line."""
    from iblbake.render import plan

    if not any(p.profiles == "paths" for p in plan(scene).passes):
        raise InputError(f"{_name(names, 'profile_paths')}: the scene has no reference pass to profile "
                         f"(effects.diffuse or effects.specular: reference)")


@_arguments
def render(scene, device: str | None = None, *, cache=None, warn=None, progress=None, profile_paths: bool = False,
           names: dict | None = None) -> Frame:
    """Render a scene once (a Scene, a scene file or a mapping; see load_scene) on `device` into a
    Frame (HDR array, tone-mapped array, report). A series of frames: use a Renderer.
    profile_paths: measure where the reference pass's time goes (Renderer.render). names: what
    error messages call each argument (by default its name; the command line passes its flags)."""
    _callback("warn", warn)
    _callback("progress", progress)
    profile_paths = _flag(_name(names, "profile_paths"), profile_paths)
    sc = load_scene(scene, names=names)            # a bad scene is said before the device starts
    if profile_paths:
        _profiled(sc, names)
    return Renderer(device, cache, reuse=False, names=names).render(sc, warn=warn, progress=progress,
                                                                    profile_paths=profile_paths)
