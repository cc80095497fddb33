"""`iblbake mips`: the radiance chain, the GGX-prefiltered chain and the DFG table, cached."""

from __future__ import annotations

import os
import time
from pathlib import Path

import click

from iblbake.cli.options import (POLICY_FLAGS, Console, cache_option, check_inputs_exist, check_suffix, common_options,
                                 depfile_option, device_option, finite, force_option, input_files_of, input_options,
                                 non_negative, panorama_reads, refuse_foreign)
from iblbake.io.guard import refuse_overlaps


def _per_env(envs, path, flag) -> dict:
    """Each ENV's output file: `path` itself for one ENV, else `path`/ENV-name.ktx2 (a folder)."""
    from iblbake.io.atomic import check_writable
    if len(envs) > 1:
        folder = Path(path)
        if folder.exists() and not folder.is_dir():
            raise click.BadParameter(f"{folder}: with several ENVs, {flag} names a folder", param_hint=flag)
        out = {env: folder / (Path(env).stem + ".ktx2") for env in envs}
    else:
        out = {envs[0]: Path(path)}
    for o in out.values():
        check_writable(o, f"{flag} output")
    return out


@click.command("mips")
@click.argument("envs", metavar="ENV...", nargs=-1, required=True)
@cache_option("Cache folder; entries go to CACHE/<key>/ with a manifest.json")
@click.option("--layout", type=click.Choice(["equirect", "cubemap", "octahedral"]), default="equirect",
              show_default=True, help="Layout of the prefiltered chain (cubemap: faces +X -X +Y -Y +Z -Z "
                                      "stacked vertically).")
@click.option("--size", type=click.IntRange(min=1), default=None,
              help="Base size of the prefiltered chain: equirect height, cube face or octahedral side. "
                   "Default: source height (cubemap: half of it).")
@click.option("--levels", type=click.IntRange(1, 32), default=None,
              help="Levels K of the prefiltered chain, roughness r_k = k/(K-1). Default: one per halving "
                   "of --size down to --min-size.")
@click.option("--min-size", type=click.IntRange(min=1), default=8, show_default=True,  # layouts.MIN_LEVEL_SIZE
              help="Smallest level size of the prefiltered chain.")
@click.option("--method", type=click.Choice(["auto", "spectral", "convolve", "fis"]), default="auto",
              show_default=True,
              help="spectral: the exact GGX convolution done in the spherical-harmonic domain (host, "
                   "ducc0; any lobe with r >= 0.06 or so); convolve: deterministic sum over every texel "
                   "of a fine enough chain level (exact, slow on sharp levels); fis: GGX importance "
                   "sampling with filtered lookups; auto: spectral where it applies, else convolve "
                   "where it fits --convolve-budget, else fis.")
@click.option("--samples", type=click.IntRange(min=1), default=256, show_default=True,
              help="GGX samples per texel for fis levels.")
@click.option("--lod-bias", type=float, default=1.0, show_default=True, callback=finite,
              help="Added to the filtered-importance-sampling level (Krivanek and Colbert use 1).")
@click.option("--no-fis", is_flag=True, help="Plain importance sampling: every sample reads level 0.")
@click.option("--convolve-budget", type=float, default=None, callback=non_negative,
              help="auto: weight evaluations per level allowed for convolve. Default: 1.5e8 on a CPU "
                   "device, 2e10 on a GPU (about half a second per level on each).")
@click.option("--dfg-size", type=click.IntRange(2, 4096), default=128, show_default=True,
              help="DFG table size (NoV x roughness).")
@click.option("--dfg-samples", type=click.IntRange(min=1), default=4096, show_default=True,
              help="GGX samples per DFG texel.")
@click.option("--dfg-multiscatter", is_flag=True,
              help="Store (B, A+B) for Filament's multiple-scattering energy compensation instead of (A, B).")
@click.option("--only", type=click.Choice(["all", "radiance", "prefiltered", "dfg"]), multiple=True,
              default=("all",), show_default=True, help="Bake only these parts (repeatable).")
@click.option("--level-sizes", type=click.Choice(["halving", "lobe"]), default="halving", show_default=True,
              help="halving: level k is --size >> k (a mip chain, what engines load); lobe: each level as fine "
                   "as its lobe needs (texels no wider than alpha/16, up to --size), what render bakes for its "
                   "equirect chain.")
@click.option("--verify", type=click.IntRange(1, 1 << 20), default=None, metavar="N",
              help="Measure each prefiltered level's relative RMSE against the float64 brute force at N "
                   "random texels, print it and store it in the entry's manifest (render --report shows it).")
@click.option("--backend", type=click.Choice(["opencl", "numpy"]), default="opencl", show_default=True,
              help="opencl: the kernels; numpy: their float64 twins (slow; small sizes).")
@click.option("--ktx2", "ktx2_path", type=click.Path(), default=None, metavar="FILE",
              help="Also write the prefiltered chain as a KTX2 cube map with its mip levels (faces +X -X +Y "
                   "-Y +Z -Z, Vulkan's orientation); implies --layout cubemap. With several ENVs, a folder "
                   "that gets ENV's name with .ktx2.")
@click.option("--ktx2-format", type=click.Choice(["rgba16f", "rgba32f", "b10g11r11", "e5b9g9r9"]), default="rgba16f",
              show_default=True,
              help="Texel format of --ktx2: R16G16B16A16_SFLOAT, R32G32B32A32_SFLOAT, B10G11R11_UFLOAT_PACK32 or "
                   "E5B9G9R9_UFLOAT_PACK32.")
@click.option("--sheen", is_flag=True,
              help="Also bake the Charlie-prefiltered (sheen) chain in the prefiltered chain's layout and sizes "
                   "(level k of roughness max(k/(K-1), 0.07)) and the sheen albedo table E(NoV, r) on the DFG "
                   "grid (KHR_materials_sheen).")
@click.option("--ktx2-sheen", "ktx2_sheen", type=click.Path(), default=None, metavar="FILE",
              help="Write the --sheen chain (implied) as a KTX2 cube map with its mip levels, as --ktx2.")
@click.option("--irradiance", "irradiance_on", is_flag=True,
              help="Also bake the Lambert irradiance cube map (the alternative to SH some engines load): "
                   "E(n) = int L max(0, n.w) dw computed in the SH domain to --irradiance-lmax, its error "
                   "against the exact sum printed.")
@click.option("--irradiance-size", type=click.IntRange(1, 1024), default=32, show_default=True,
              help="Face size of the --irradiance cube map.")
@click.option("--irradiance-lmax", type=click.IntRange(2, 2048), default=256, show_default=True,
              help="SH band limit of the --irradiance cube map (the only approximation in it).")
@click.option("--ktx2-irradiance", "ktx2_irradiance", type=click.Path(), default=None, metavar="FILE",
              help="Write the --irradiance cube map (implied) as a KTX2 cube map in --ktx2-format. With "
                   "several ENVs, a folder that gets ENV's name with .ktx2.")
@depfile_option
@force_option
@input_options
@device_option
@common_options
def mips_command(envs, cache_dir, layout, size, levels, min_size, method, samples, lod_bias, no_fis,
                 convolve_budget, dfg_size, dfg_samples, dfg_multiscatter, only, level_sizes, verify, backend,
                 ktx2_path, ktx2_format, sheen, ktx2_sheen, irradiance_on, irradiance_size, irradiance_lmax, ktx2_irradiance, nonfinite,
                 negative, transfer, primaries, input_layout, max_pixels, depfile, force, device, quiet, as_json):
    """Bake the radiance mip chain, the GGX-prefiltered chain and the DFG table of each ENV into a
    content-addressed EXR cache (one process and one device for a whole folder). A second run
    with the same inputs does no work ("cached"). With --depfile the entries' manifests depend on
    their panorama."""

    from iblbake.bake import cache
    from iblbake.io import images
    from iblbake.bake import layouts
    from iblbake.bake import mips as mipsbake

    con = Console(quiet, as_json)
    parts = {"radiance", "prefiltered", "dfg"} if "all" in only else set(only)
    ktx2_out, irr_out, sheen_out = {}, {}, {}
    sheen = sheen or bool(ktx2_sheen)
    if sheen and "prefiltered" not in parts:
        raise click.UsageError("--sheen bakes alongside the prefiltered chain (its layout and sizes): "
                               "give --only prefiltered (or all)")
    if ktx2_sheen:
        if level_sizes != "halving" or (click.get_current_context().get_parameter_source("layout")
                                        == click.core.ParameterSource.COMMANDLINE and layout != "cubemap"):
            raise click.UsageError("--ktx2-sheen writes a cube map mip chain: --layout cubemap, --level-sizes halving")
        layout = "cubemap"
        sheen_out = _per_env(envs, ktx2_sheen, "--ktx2-sheen")
    irradiance_on = irradiance_on or bool(ktx2_irradiance)
    if ktx2_irradiance:
        irr_out = _per_env(envs, ktx2_irradiance, "--ktx2-irradiance")
    if ktx2_path:
        ctx = click.get_current_context()
        if ctx.get_parameter_source("layout") == click.core.ParameterSource.COMMANDLINE and layout != "cubemap":
            raise click.UsageError(f"--ktx2 writes a cube map: leave out --layout {layout} (or give cubemap)")
        if "prefiltered" not in parts:
            raise click.UsageError("--ktx2 writes the prefiltered chain: give --only prefiltered (or all)")
        if level_sizes != "halving":
            raise click.UsageError("--ktx2 stores a mip chain: give --level-sizes halving")
        layout = "cubemap"
        ktx2_out = _per_env(envs, ktx2_path, "--ktx2")
    writes = [(flag, str(p)) for flag, outs in (("--ktx2", ktx2_out), ("--ktx2-irradiance", irr_out),
                                                 ("--ktx2-sheen", sheen_out)) for p in outs.values()]
    writes += [("--depfile", depfile)] if depfile else []
    refuse_overlaps(writes, panorama_reads(envs))
    if len(envs) == 1:
        for flag, p in writes:
            if flag != "--depfile":
                check_suffix(p, (".ktx2",), flag, "a KTX2 cube map")
    from iblbake.io import atomic
    for _, p in writes:              # before any bake: a read-only folder is not found at the end
        atomic.check_writable(p)
    refuse_foreign(writes, force)
    check_inputs_exist(envs)
    # every output is written once every panorama has baked: a bad one among several leaves none
    pending = []
    t_start = time.perf_counter()
    root = Path(cache_dir) if cache_dir else cache.default_root()
    from iblbake.io.atomic import check_writable
    check_writable(root / "manifest.json", "cache", shown=root)
    baker = mipsbake.Baker(backend, device)

    def chain_options(height=0):
        return mipsbake.PrefilterOptions(layout, size, levels, min_size, method, samples, lod_bias, not no_fis,
                                         convolve_budget, level_sizes).resolved(height)

    def check_size(height=0):         # --size (or the source's height it defaults to) against memory
        if "prefiltered" in parts:
            mipsbake.check_chain_fits(layout, chain_options(height)["base_size"],
                                      lambda s: mipsbake.PrefilterOptions(
                                          layout, s, levels, min_size, level_sizes=level_sizes).resolved(0)["sizes"],
                                      baker.rt, "--size")
    if size is not None:
        check_size()
    summaries, rules = [], []
    for env in envs:
        report = {}
        summaries.append({"input": env, "cache": str(root), "device": baker.device_label, "entries": report})
        if parts & {"radiance", "prefiltered"} or irradiance_on:
            from iblbake.bake import inputs
            image, info = inputs.read_environment(env, layout=input_layout, runtime=baker.rt, max_pixels=max_pixels,
                                                  nonfinite=nonfinite,
                                                  negative=negative, transfer=transfer, primaries=primaries,
                                                  names=POLICY_FLAGS)
            for w in info.warnings:
                con.warn(w)
            policies = images.read_policies(nonfinite, negative, transfer, primaries, input_layout)
            if "prefiltered" in parts:
                if size is None:
                    check_size(info.height)
                opts = chain_options(info.height)
                for out in (ktx2_out.get(env), sheen_out.get(env)):
                    if out is not None:
                        mipsbake.check_ktx2_chain(out, opts)
                # an impossible plan (--method spectral on a too sharp level) fails before any bake
                mipsbake.plan_methods(layouts.radiance_chain_sizes(info.width, info.height),
                                      {**opts, "convolve_budget": baker.convolve_budget(opts)}, "--method")
            if irradiance_on:
                t0 = time.perf_counter()
                im, icached, faces = mipsbake.bake_irradiance_cube(image, info, root, policies, irradiance_size,
                                                                   irradiance_lmax, warn=con.warn)
                report["irradiance"] = {"path": str(root / im["key"]), "cached": icached, "size": irradiance_size,
                                        "lmax": irradiance_lmax, "error": im["error"],
                                        "seconds": round(time.perf_counter() - t0, 4)}
                if env in irr_out:
                    pending.append(lambda b, o=irr_out[env], f=faces: mipsbake.write_irradiance_ktx2(o, f, ktx2_format, b))
                    report["ktx2_irradiance"] = {"path": str(irr_out[env]), "format": ktx2_format, "cached": False,
                                                 "seconds": 0.0}
            if not parts & {"radiance", "prefiltered"}:
                entries = [Path(e["path"]) / "manifest.json" for k, e in report.items() if not k.startswith("ktx2")]
                rules.append(([str(x) for x in entries], [os.path.abspath(f) for f in input_files_of(env)]))
                continue
            t0 = time.perf_counter()
            manifest, cached, chain = mipsbake.bake_radiance(baker, image, info, root, policies, warn=con.warn)
            report["radiance"] = {"path": str(root / manifest["key"]), "cached": cached,
                                  "seconds": round(time.perf_counter() - t0, 4), "levels": len(manifest["files"])}
            if "prefiltered" in parts:
                chain_levels = mipsbake.chain_loader(root, manifest, chain)
                levels_named = [f"level {k} (r = {r:.3g})" for k, r in enumerate(opts["roughness"])]
                with con.stages(levels_named, label="prefiltering") as step:
                    t0 = time.perf_counter()
                    pm, pcached = mipsbake.bake_prefiltered(baker, chain_levels, info, root, policies, opts,
                                                            warn=con.warn, progress=step)
                report["prefiltered"] = {"path": str(root / pm["key"]), "cached": pcached,
                                         "seconds": round(time.perf_counter() - t0, 4), "layout": layout,
                                         "sizes": opts["sizes"], "roughness": opts["roughness"],
                                         "methods": [f["method"] for f in pm["files"]]}
                if verify:
                    report["prefiltered"]["verify"] = mipsbake.verify_prefiltered(root, pm, image, verify)
                if sheen:
                    t0 = time.perf_counter()
                    sm, scached = mipsbake.bake_sheen(image, info, root, policies, opts, warn=con.warn)
                    report["sheen"] = {"path": str(root / sm["key"]), "cached": scached,
                                       "seconds": round(time.perf_counter() - t0, 4), "layout": layout,
                                       "roughness": [f["roughness"] for f in sm["files"]]}
                    if env in sheen_out:
                        mipsbake.check_ktx2_chain(sheen_out[env], opts)
                        pending.append(lambda b, o=sheen_out[env], m=sm, op=opts: mipsbake.write_ktx2(
                            o, root, m, {**op, "roughness": mipsbake.sheen_roughness(op["roughness"])},
                            ktx2_format, content="Charlie-prefiltered (sheen) radiance", batch=b))
                        report["ktx2_sheen"] = {"path": str(sheen_out[env]), "format": ktx2_format, "cached": False,
                                                "seconds": 0.0}
                if env in ktx2_out:
                    out = ktx2_out[env]
                    rep = report["ktx2"] = {"path": str(out), "format": ktx2_format, "cached": False,
                                            "seconds": 0.0, "levels": len(opts["sizes"])}

                    def ktx2_write(b, out=out, m=pm, op=opts, rep=rep):
                        t0 = time.perf_counter()
                        mipsbake.write_ktx2(out, root, m, op, ktx2_format, batch=b)
                        rep["seconds"] = round(time.perf_counter() - t0, 4)
                    pending.append(ktx2_write)
        entries = [Path(e["path"]) / "manifest.json" for k, e in report.items() if not k.startswith("ktx2")]
        entries += [report[k]["path"] for k in ("ktx2", "ktx2_irradiance", "ktx2_sheen") if k in report]
        if entries:
            rules.append(([str(x) for x in entries], [os.path.abspath(f) for f in input_files_of(env)]))
    if sheen:                         # shared by every panorama, as the DFG table
        t0 = time.perf_counter()
        shm, shcached = mipsbake.bake_sheen_dfg(baker, root, dfg_size, dfg_samples, warn=con.warn)
        for s in summaries:
            s["entries"]["dfg_sheen"] = {"path": str(root / shm["key"]), "cached": shcached,
                                         "seconds": round(time.perf_counter() - t0, 4)}
    if "dfg" in parts:                # shared by every panorama: baked once
        t0 = time.perf_counter()
        dm, dcached = mipsbake.bake_dfg(baker, root, dfg_size, dfg_samples, dfg_multiscatter, warn=con.warn)
        dfg_entry = {"path": str(root / dm["key"]), "cached": dcached, "seconds": round(time.perf_counter() - t0, 4)}
        for s in summaries:
            s["entries"]["dfg"] = dfg_entry
    with atomic.Batch() as batch:    # every KTX2 file and the depfile, together
        for write in pending:
            write(batch)
        if depfile:
            from iblbake.io import depfile as dep
            dep.write(depfile, rules, batch)
    elapsed = round(time.perf_counter() - t_start, 4)
    lines = []
    for s in summaries:
        s["elapsed_s"] = elapsed
        lines += [f"{kind}: {'wrote' if kind.startswith('ktx2') else 'cached' if e['cached'] else 'baked'} {e['path']} "
                  f"({e['seconds']:.3f} s)" for kind, e in s["entries"].items() if kind != "dfg"]
        ie = s["entries"].get("irradiance", {}).get("error")
        if ie:
            lines.append(f"irradiance cube: against the exact sum at {ie['normals']} normals, worst "
                         f"{100 * ie['max_relative_to_peak']:.3f}% of the peak, RMS {100 * ie['rms_relative_to_peak']:.4f}%")
        v = s["entries"].get("prefiltered", {}).get("verify")
        if v:
            lines.append(f"verify: relative RMSE per level against the brute force at {v['texels_per_level']} texels: "
                         + " ".join(f"{100 * e:.2f}%" for e in v["relative_rmse"]))
    if "dfg" in parts:
        lines.append(f"dfg: {'cached' if dfg_entry['cached'] else 'baked'} {dfg_entry['path']} "
                     f"({dfg_entry['seconds']:.3f} s)")
    lines.append(f"done in {elapsed:.3f} s on {baker.device_label}")
    con.result(summaries[0] if len(summaries) == 1 else {"panoramas": summaries}, "\n".join(lines))
