"""`iblbake lightmap`: bake a scene's lightmap into the files an engine loads."""

from __future__ import annotations

from pathlib import Path

import click

from iblbake.cli.options import (API_FLAGS, Console, cache_option, refuse_foreign, scene_options,
                                 written_lights_said)


@click.command("lightmap")
@click.argument("scene_path", metavar="SCENE")
@click.option("--output", "-o", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Folder for lightmap.json, the atlases (EXR and KTX2), lightmap.gltf (+ .bin, .png) and the "
                   "GLSL; created if missing. Files of those names iblbake wrote are replaced (together, "
                   "atomically); other files need --force.")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scene value, e.g. --set lightmap.texels_per_unit=4 (as render --set).")
@cache_option("Bake cache folder (as render)")
@scene_options
def lightmap_command(scene_path, out_dir, overrides, cache_dir, force, device, quiet, as_json):
    """Bake the lightmap of SCENE (its `lightmap:` section; see render --help-schema) by tracing
    paths from every texel of its static geometry, and write each basis the bake holds as fp16
    atlases (EXR and KTX2) with a JSON manifest (their layout, units, density and how to evaluate
    the irradiance at a normal) and GLSL that samples them, and the geometry as glTF with
    TEXCOORD_1 and the lightmap (the IBLBAKE_lightmap extension, docs/conventions.md)."""
    from iblbake import api
    from iblbake.api.lightmaps import declared
    from iblbake.io import atomic
    from iblbake.io.guard import refuse_overlaps
    from iblbake.render.lightmaps import export
    from iblbake.scene import load as scene

    con = Console(quiet, as_json)
    sc = api.load_scene(scene_path, overrides, outputs=[], names=API_FLAGS)
    if not declared(sc):      # before the folder's checks (the library says it too)
        raise click.UsageError(f"{scene_path}: the scene has no `lightmap:` section; add one (`lightmap: {{}}` "
                               f"takes the defaults) or --set lightmap.texels_per_unit=N")
    out = Path(out_dir)
    # every file a bake may write, checked before it (a refused folder costs no bake)
    settings = sc.data["lightmap"]
    writes = [("--output", out / n) for n in export.file_names(export.expected(settings), settings,
                                                               environment=sc.data["environment"]["sun"] == "extract")]
    refuse_overlaps(writes, scene.named_input_files(sc))
    for _flag, p in writes:
        atomic.check_writable(p)
    refuse_foreign(writes, force)
    with con.fraction("lightmap", "texel rays") as progress:
        lm = api.bake_lightmap(sc, device, cache=cache_dir, warn=con.warn, progress=progress, names=API_FLAGS)
    names = lm.files()
    man = lm.write(out)
    removed = _remove_stale(out, names)
    r = man["report"]
    summary = {"scene": sc.source, "output": str(out), "files": names, "cached": lm.cached, "device": lm.device,
               "width": lm.width, "height": lm.height, "texels_per_unit": man["atlas"]["texels_per_unit"],
               "bases": list(man["bases"]), "texels": r["texels"], "rays_traced": r["rays_traced"],
               "bake_s": r["seconds"], "bytes": r.get("bytes", {})}
    if removed:
        summary["removed"] = removed
    con.result(summary, f"wrote {out}/ ({lm.width}x{lm.height} atlas at {man['atlas']['texels_per_unit']:g} texels a "
                        f"unit, {', '.join(man['bases'])}; {r['texels']} texels, {r['rays_traced']} rays in "
                        f"{r['seconds']:.2f} s{' (cached)' if lm.cached else ''} on {lm.device})"
                        f"{written_lights_said(man['lights'], 'lightmap.json', 'the atlases')}")


def _remove_stale(out: Path, names: list) -> list:
    """The atlases and GLSL of another basis an earlier call left in the folder, which iblbake
    wrote: removed, so that the folder holds this bake's files alone (a user's own are left)."""
    from iblbake.io.guard import written_by_iblbake
    from iblbake.render.lightmaps.export import STEM
    removed = []
    for f in sorted(out.glob(f"{STEM}_*")):
        if f.name not in names and f.suffix in (".exr", ".ktx2", ".glsl") and f.is_file() and not f.is_symlink() \
                and written_by_iblbake(f):
            f.unlink()
            removed.append(f.name)
    return removed
