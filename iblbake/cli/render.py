"""`iblbake render`: a scene YAML through the renderer's passes into frames."""

from __future__ import annotations

import contextlib
import json

import click

from iblbake.cli.options import (API_FLAGS, Console, allow_outside_option, cache_option, common_options, extracted_said,
                                 depfile_option, refuse_foreign, scene_options)


def _help_schema(ctx, param, value):
    if value and not ctx.resilient_parsing:
        from iblbake.scene.schema import schema_text
        click.echo(schema_text(), nl=False)
        ctx.exit(0)


@click.command("render")
@click.argument("scene_path", metavar="SCENE", required=False)
@click.option("--output", "-o", "outputs", multiple=True, type=click.Path(dir_okay=False),
              help="Frame path (.png tone-mapped, .exr linear); repeatable. Replaces output.frame of the "
                   "scene. Earlier frames iblbake wrote are replaced (atomically); other files need --force.")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scene value, e.g. --set effects.samples=40 --set materials.gold.roughness=0.3 "
                   "--set objects.0.sphere.radius=2 (repeatable; values parse as YAML).")
@cache_option("Bake cache folder (shared with `iblbake mips`)")
@click.option("--report", "show_report", is_flag=True,
              help="Print the effect set, every bake and pass with its time and cache hit/miss, and the device.")
@click.option("--profile-paths", is_flag=True,
              help="After the frame, measure where the reference pass's time goes, per bounce: shading, "
                   "closest-hit and shadow-ray traversal (more launches of its first batch, medians of 5 rounds; "
                   "the frame is the same). Printed, and in --json as paths_profile. Needs the reference.")
@click.option("--help-schema", is_flag=True, expose_value=False, is_eager=True, callback=_help_schema,
              help="Print every scene key with its type, range and default, and exit.")
@depfile_option
@scene_options
def render_command(scene_path, outputs, overrides, cache_dir, show_report, profile_paths, depfile, force, device, quiet,
                   as_json):
    """Render the scene file SCENE (YAML; see --help-schema and examples/scenes/) with OpenCL.

    Only the effects the scene calls for are baked, compiled and run; --report shows which.
    """
    from iblbake import api
    from iblbake.render import plan, write_outputs
    from iblbake.scene import load as scene

    if scene_path is None:
        raise click.UsageError("missing SCENE (a scene YAML file; see --help-schema)")
    con = Console(quiet, as_json)
    sc = api.load_scene(scene_path, overrides, outputs=outputs, names=API_FLAGS)
    from iblbake.io.atomic import check_writable
    from iblbake.io.guard import refuse_overlaps
    writes = sc.writes + ([("--depfile", depfile)] if depfile else [])
    refuse_overlaps(writes, scene.named_input_files(sc))
    for _, p in writes:              # every output, the depfile too, before the frame is rendered
        check_writable(p)
    refuse_foreign(writes, force)
    pl = plan(sc)
    # paths (the reference, probe rays, reflection captures, lightmap texels): a bar on a terminal
    long_work = "reference" in pl.pass_names or {"probes", "reflection_probes", "lightmap"} & set(pl.bakes)
    with con.fraction("render", "paths") if long_work else contextlib.nullcontext(None) as progress:
        frame = api.render(sc, device, cache=cache_dir, warn=con.warn, progress=progress, profile_paths=profile_paths,
                           names=API_FLAGS)
    written = write_outputs(frame, sc)
    if depfile:
        from iblbake.io import depfile as dep
        dep.write(depfile, [(written, scene.input_files(sc))])
    rep = frame.report
    summary = {**rep, "scene": sc.source, "outputs": written}
    lines = []
    if show_report:
        e = rep["effects"]
        lines.append(f"device: {rep['device']}")
        lines.append(f"effects: diffuse={e['diffuse']} specular={e['specular']} background={e['background']}"
                     f"{' emissive' if e['emissive'] else ''}{' reflection_probes' if e['reflection_probes'] else ''}"
                     f"{' ssr' if e['ssr'] else ''}")
        for name, defs in e["defines"].items():
            lines.append(f"defines {name}: " + (" ".join(f"{k}={v}" for k, v in defs.items()) or "-"))
        for b in rep["bakes"]:
            extra = " ".join(f"{k}={_plain(v)}" for k, v in b.items() if k not in ("name", "seconds", "cached",
                                                                                    "entry", "meshes"))
            lines.append(f"bake  {b['name']:<16} {b['seconds']:8.3f} s  {'hit ' if b['cached'] else 'miss'}  {extra}")
        for p in rep["passes"]:
            extra = " ".join(f"{k}={_plain(v)}" for k, v in p.items() if k not in ("name", "seconds"))
            lines.append(f"pass  {p['name']:<16} {p['seconds']:8.3f} s        {extra}")
        for b in rep["kernel_builds"]:
            lines.append(f"build {b['kernel']:<16} {b['seconds']:8.3f} s")
    if "paths_profile" in rep:
        lines.extend(profile_lines(rep["paths_profile"]))
    w, h = rep["resolution"]
    lines.append(f"{'wrote ' + ', '.join(written) if written else 'rendered'} ({w}x{h}, {_samples(rep)}) "
                 f"in {rep['elapsed_s']:.3f} s on {rep['device']}{_extracted(sc, rep)}")
    con.result(summary, "\n".join(lines))


def _extracted(sc, rep) -> str:
    """What `environment.sun: auto` took out of the panorama (a new user's trial: the frames of
    `sun: none` and the default differed and nothing but --report said why)."""
    lit = next((p for p in rep["passes"] if p["name"] == "lights"), {})
    n = len(lit.get("extracted") or [])
    if ((sc.raw or {}).get("environment") or {}).get("sun", "auto") != "auto":
        return ""
    from iblbake.scene.load import has_probes
    held = "probes" if has_probes(sc.data, sc.raw or {}) else "a lightmap"
    return extracted_said(n, " and lit per pixel", "it", why=f"environment.sun: auto, the scene has {held}; ")


def _plain(value) -> str:
    """A report's value as --report shows it: a dict or list as JSON (numpy's floats plainly,
    not np.float64(0.93) as their repr reads)."""
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value, default=lambda v: v.item() if hasattr(v, "item") else str(v))
    return str(value)


def profile_lines(pr: dict) -> list:
    """The reference's paths profile (render/paths/profile.py) as a table: per bounce its time,
    split into shading and the traversal of its closest-hit and shadow rays."""
    unit = "CPU ms" if pr["clock"] == "cpu" else "ms"
    tile = f", tile {pr['tile']} of {pr['tiles']}" if pr["tiles"] > 1 else ""
    fewer = f" (of the frame's {pr['frame_batch']}: the rays' record)" if pr["batch"] != pr["frame_batch"] else ""
    clock = "CPU time of this process (the device's threads)" if pr["clock"] == "cpu" else "wall time"
    out = [f"paths profile: the reference's first batch{tile}, {pr['gbuffer_samples']} G-buffer samples x "
           f"{pr['batch']}{fewer}, bounces {pr['bounces']}{'' if pr['visibility'] else ' (visibility off: no ray)'}; "
           f"medians of {pr['repeats']} rounds after a warm-up, {clock}",
           f"  {'':<7}{'':>9} {'':>6} {'':>6} {'':>9} {'traversal':^19}  {'rays/sample':^14}  {'Msamples/s':>14}",
           f"  {'bounce':<7}{unit:>9} {'+-':>6} {'share':>6} {'shading':>9} {'closest':>9} {'shadow':>9}"
           f"  {'closest':>7}{'shadow':>7}  {'up to it, wall':>14}"]
    for e in pr["per_bounce"]:
        share = "-" if e["share"] is None else f"{100 * e['share']:.1f}%"
        rate = "-" if e["msamples_per_s"] is None else f"{e['msamples_per_s']:.3f}"
        out.append(f"  {e['bounce']!s:<7}{e['ms']:9.1f} {e['spread_ms']:6.1f} {share:>6} {e['shading_ms']:9.1f} "
                   f"{e['traversal_closest_ms']:9.1f} {e['traversal_shadow_ms']:9.1f}  "
                   f"{e['closest_rays_per_sample']:7.3f}{e['shadow_rays_per_sample']:7.3f}  {rate:>14}")
    shading = sum(e["shading_ms"] for e in pr["per_bounce"])
    closest = sum(e["traversal_closest_ms"] for e in pr["per_bounce"])
    shadow = sum(e["traversal_shadow_ms"] for e in pr["per_bounce"])
    rays = pr["rays"] / pr["samples"]
    rate = "-" if pr["msamples_per_s"] is None else f"{pr['msamples_per_s']:.3f}"
    out.append(f"  {'whole':<7}{pr['whole_ms']:9.1f} {pr['whole_spread_ms']:6.1f} {'100%':>6} {shading:9.1f} "
               f"{closest:9.1f} {shadow:9.1f}  {rays:10.3f} all  {rate:>14}")
    if pr["per_bounce_over_whole"] is None:         # a launch too short for the clock
        return out
    check = f"  check: the bounces add up to {100 * pr['per_bounce_over_whole']:.1f}% of the whole"
    if pr["replay_and_traversal_over_whole"] is not None:
        same = "its sums the same bit for bit" if pr["replay_same_result"] else "ITS SUMS DIFFER"
        check += (f"; shading replayed with every ray's answer recorded ({pr['replay_ms']:.1f}, {same}) + "
                  f"traversal alone ({pr['traversal_ms']:.1f}) = {100 * pr['replay_and_traversal_over_whole']:.1f}%")
    out.append(check)
    built = f"{pr['programs_built']} program{'s' if pr['programs_built'] != 1 else ''}"
    out.append(f"  the whole launch {pr['whole_wall_ms']:.1f} ms of wall time; profiled in {pr['seconds']:.1f} s "
               f"({built} built in {pr['build_s']:.1f} s)")
    return out


def _samples(rep: dict) -> str:
    """The frame's samples per pixel as it was lit: a path-traced reference's own count (where it
    stopped), not the G-buffer's camera.spp."""
    ref = next((p for p in rep["passes"] if p["name"] == "reference"), None)
    if ref is None or "samples_per_pixel" not in ref:
        return f"{rep['spp']} spp"
    why = f", stopped by {ref['stopped']}" if ref.get("stopped") else ""
    return f"{ref['samples_per_pixel']} samples per pixel (reference{why})"


@click.command("deps")
@click.argument("scene_path", metavar="SCENE")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE", help="As render --set.")
@click.option("--output", "-o", "outputs", multiple=True, type=click.Path(dir_okay=False),
              help="The targets (as render -o). Default: the scene's output.frame and AOVs.")
@allow_outside_option
@common_options
def deps_command(scene_path, overrides, outputs, quiet, as_json):
    """Print the Make rule that `render --depfile` writes: SCENE's outputs depend on the scene file,
    its panorama and its meshes."""
    from iblbake import api
    from iblbake.errors import UsageError
    from iblbake.io.depfile import rule
    from iblbake.render import output_paths
    from iblbake.scene import load as scene

    sc = api.load_scene(scene_path, overrides, outputs=outputs or None, names=API_FLAGS)
    targets = output_paths(sc)
    if not targets:          # the scene itself is no target: make would "remake" the scene file
        raise UsageError(f"{scene_path}: the scene names no output (output.frame) and no -o was given; "
                         f"name the rule's target with -o FRAME.png, as render -o would write it")
    inputs = scene.input_files(sc)
    text = rule(targets, inputs)
    Console(quiet, as_json).result({"targets": targets, "prerequisites": inputs, "rule": text}, text[:-1])
