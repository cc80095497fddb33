"""`iblbake probes`: bake a scene's irradiance probe volume (and its reflection probes' captures)
into files an engine reads."""

from __future__ import annotations

from pathlib import Path

import click

from iblbake.cli.options import (API_FLAGS, Console, cache_option, refuse_foreign, scene_options,
                                 written_lights_said)


@click.command("probes")
@click.argument("scene_path", metavar="SCENE")
@click.option("--output", "-o", "out_dir", required=True, type=click.Path(file_okay=False),
              help="Folder for probes.json, the atlases (EXR) and probes.glsl; created if missing. Files of "
                   "those names iblbake wrote are replaced (together, atomically); other files need --force.")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scene value, e.g. --set probes.rays=512 --set probes.irradiance=sh (as render --set).")
@cache_option("Bake cache folder (as render)")
@scene_options
def probes_command(scene_path, out_dir, overrides, cache_dir, force, device, quiet, as_json):
    """Bake the irradiance probes of SCENE (its `probes:` section; see render --help-schema) by
    tracing paths from every probe, and write them as RTXGI-layout EXR atlases with a JSON
    manifest and a GLSL function that samples them, and each reflection probe's capture
    (reflection_K.exr: the scene's radiance, its coverage, the sky seen past it and the distance, docs/conventions.md
    "Reflection probes"; `iblbake mips` prefilters its RGB). `render` bakes the same volume on demand
    (cached by content) where a scene sets effects.diffuse: probes."""
    from iblbake import api
    from iblbake.io import atomic
    from iblbake.io.guard import refuse_overlaps
    from iblbake.scene import load as scene

    con = Console(quiet, as_json)
    sc = api.load_scene(scene_path, overrides, outputs=[], names=API_FLAGS)
    if not sc.data["objects"]:       # a usage error here, before the folder's checks (the library says it too)
        raise click.UsageError(f"{scene_path}: the scene has no objects; probes light objects (add some)")
    from iblbake.core.bases.probes import PROBE_BASES
    out = Path(out_dir)
    basis = PROBE_BASES[sc.data["probes"]["irradiance"]]
    captures = [f"reflection_{k}.exr" for k in range(len(sc.data["reflection_probes"]))]
    table = [basis.specular_table] if basis.specular_table else []     # probes.glsl's specular reads it
    from iblbake.render import probes
    names = ["probes.json", basis.file, "distance.exr", "probe_data.exr", "probes.glsl", *table, *captures]
    residual = [probes.ENVIRONMENT_FILE] if sc.data["environment"]["sun"] == "extract" else []   # if lights are found
    writes = [("--output", out / n) for n in names + residual]
    refuse_overlaps(writes, scene.named_input_files(sc))
    for n in names + residual:       # the folder is made when the files are written, not before
        atomic.check_writable(out / n)
    refuse_foreign(writes, force)
    with con.fraction("probes", "probe rays") as progress:
        vol = api.bake_probes(sc, device, cache=cache_dir, warn=con.warn, progress=progress, names=API_FLAGS)
    man, cached = vol.manifest, vol.cached
    names += residual if vol.environment is not None else []
    entry = Path(vol.entry)
    from iblbake.io import images, reads
    from iblbake.render import reflection_probes
    with atomic.Batch() as batch:    # every file of the folder replaced together, or none
        for name, c in zip(captures, vol.reflections):     # an engine prefilters them (iblbake mips --ktx2)
            images.write_exr(out / name, c["capture"], channels=reflection_probes.CHANNELS, batch=batch)
        for n in names[1:4]:         # the cache entry's atlases (verified against their manifest)
            batch.write_bytes(out / n, reads.read_bytes(entry / n, 1 << 40, "a cached atlas"))
        if table:
            images.write_exr(out / table[0], basis.table_image(), channels=("R",), batch=batch)
        if vol.environment is not None:      # what an engine prefilters for the specular (probes.json's environment)
            probes.write_environment(vol.environment, out / probes.ENVIRONMENT_FILE, batch)
        batch.write_json(out / "probes.json", man)
        batch.write_text(out / "probes.glsl", vol.glsl())
    removed = _remove_stale(out, names)
    r = man["report"]
    summary = {"scene": sc.source, "output": str(out), "files": names, "cached": cached, "device": vol.device,
               "grid": man["grid"], "representation": man["representation"], "states": man["states"],
               "rays_traced": r["rays_traced"], "bake_s": r["seconds"], "relocated": r["relocated"],
               "inside_geometry": r.get("inside_geometry", 0), "outside_camera_room": r.get("outside_camera_room", 0),
               "off_by": r.get("off_by", {}), "more_rays": r.get("more_rays", {}),
               "lights": len(man["lights"]), **({"estimate": r["estimate"]} if "estimate" in r else {})}
    if removed:
        summary["removed"] = removed
    nx, ny, nz = man["grid"]["counts"]
    con.result(summary, f"wrote {out}/ ({nx}x{ny}x{nz} probes, {man['representation']}, "
                        f"{man['states']['inactive']} inactive, {r['relocated']} relocated; "
                        f"{r['rays_traced']} rays{more_said(r.get('more_rays', {}))} in {r['seconds']:.2f} s"
                        f"{' (cached)' if cached else ''} "
                        f"on {vol.device}){written_lights_said(man['lights'], 'probes.json', 'the probes')}")


def more_said(more: dict) -> str:
    """The noisy probes' further rays (render/probes/adaptive.py): ' (2048 rays: 40 probes, ...)'."""
    return f" ({', '.join(f'{n} rays: {c} probes' for n, c in more.items())})" if more else ""


def _remove_stale(out: Path, names: list) -> list:
    """The files an earlier bake of another representation (or with more reflection probes) left in
    the folder, which iblbake wrote: removed, so that an engine that reads the folder finds this
    volume's files alone (a user's own files are left)."""
    from iblbake.io.guard import written_by_iblbake
    from iblbake.render import probes
    stale = {*probes.FILES.values(), *probes.SPECULAR_TABLES, probes.ENVIRONMENT_FILE,
             *(p.name for p in out.glob("reflection_*.exr"))} - set(names)
    removed = []
    for n in sorted(stale):
        f = out / n
        if f.is_file() and not f.is_symlink() and written_by_iblbake(f):
            f.unlink()
            removed.append(n)
    return removed
