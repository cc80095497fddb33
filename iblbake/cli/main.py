"""The `iblbake` command line: thin click commands that parse, call the library and print.

Errors the user can act on are the library's IblbakeError (iblbake.errors, plain exceptions): printed
here as one line, exit != 0.
Anything else is an internal error: one line too, unless --debug asks for the traceback.
Heavy modules (pyopencl, OpenImageIO, trimesh) are imported inside the commands that use them.
"""

from __future__ import annotations

if __name__ == "__main__":   # python -m iblbake.cli: a Ctrl-C during the imports below exits quietly
    from iblbake.entry import quiet_startup
    quiet_startup()

import contextlib
import json
import math
import os
import sys
import time

import click

from iblbake import __version__
from iblbake.errors import IblbakeError

_DEBUG = {"on": bool(os.environ.get("IBLBAKE_DEBUG"))}


class IblbakeGroup(click.Group):
    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except (IblbakeError, click.ClickException, click.exceptions.Exit, click.exceptions.Abort):
            raise
        except KeyboardInterrupt:
            raise click.exceptions.Abort() from None
        except Exception as e:
            if _DEBUG["on"]:
                raise
            text = " ".join(str(e).split())[:300]
            raise IblbakeError(
                f"internal error: {type(e).__name__}: {text} (rerun with --debug for the traceback)") from None


def _set_debug(ctx, param, value):
    if value:
        _DEBUG["on"] = True
    return value


class Console:
    """Where a command's human output goes: notes and warnings on stderr, silenced by --quiet;
    machine-readable JSON on stdout with --json."""

    def __init__(self, quiet: bool, as_json: bool):
        self.quiet, self.as_json = quiet, as_json

    def note(self, text: str):
        if not self.quiet:
            click.echo(text, err=True)

    def warn(self, text: str):
        if not self.quiet:
            click.echo(f"iblbake: warning: {text}", err=True)

    @property
    def interactive(self) -> bool:
        return not self.quiet and sys.stderr.isatty() and not os.environ.get("CI")

    @contextlib.contextmanager
    def stages(self, names, label: str):
        """A progress bar over named stages on an interactive terminal; silent otherwise.
        Yields a function that marks the current stage done."""
        if not self.interactive:
            yield lambda _=1: None
            return
        names = list(names)
        with click.progressbar(length=len(names), label=label, file=sys.stderr,
                               item_show_func=lambda i: i) as bar:
            done = [0]

            def step(_=1):   # also fits callers that report progress(1)
                done[0] += 1
                bar.update(1, names[done[0]] if done[0] < len(names) else "done")
            bar.update(0, names[0])
            yield step

    def result(self, summary: dict, human: str):
        if self.as_json:
            click.echo(json.dumps(summary, indent=2, allow_nan=False))
        elif not self.quiet:
            click.echo(human)


def common_options(f):
    """--json, --quiet, --debug, shared by every command."""
    f = click.option("--debug", is_flag=True, expose_value=False, is_eager=True, callback=_set_debug,
                     help="Show tracebacks for internal errors.")(f)
    f = click.option("--quiet", "-q", is_flag=True, help="Print nothing but errors.")(f)
    f = click.option("--json", "as_json", is_flag=True, help="Print a machine-readable JSON summary on stdout.")(f)
    return f


def device_option(f):
    return click.option("--device", "-d", default=None, metavar="SPEC", show_default=False,
                        help="OpenCL device: 'gpu', 'cpu', 'P:D' (platform:device index) or part of "
                             "its name. Default: $IBLBAKE_DEVICE, else the first working GPU, else CPU.")(f)


def input_options(f):
    """Options for reading a panorama, shared by sh and mips."""
    f = click.option("--max-pixels", type=click.IntRange(min=1), default=None,
                     help="Refuse larger images before decoding them. Default: $IBLBAKE_MAX_PIXELS "
                          "or 8192*8192.")(f)
    f = click.option("--negative", type=click.Choice(["keep", "clamp", "error"]), default="keep",
                     show_default=True,
                     help="Negative texels: keep as stored (counted and reported), clamp to 0, or fail.")(f)
    f = click.option("--nonfinite", type=click.Choice(["error", "zero", "clamp"]), default="error",
                     show_default=True,
                     help="NaN/Inf texels: fail (naming the count and first position), set to 0, or "
                          "clamp (+Inf to the largest finite value, NaN and -Inf to 0).")(f)
    return f


# the read policies as this command line names them (the library's messages quote these)
POLICY_FLAGS = {"max_pixels": "--max-pixels", "nonfinite": "--nonfinite", "negative": "--negative"}


def _finite(ctx, param, value):
    if value is not None and not math.isfinite(value):
        raise click.BadParameter(f"{value} is not a finite number")
    return value


def _non_negative(ctx, param, value):
    value = _finite(ctx, param, value)
    if value is not None and value < 0:
        raise click.BadParameter(f"{value} is negative; give a value >= 0")
    return value


@click.group(cls=IblbakeGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="iblbake")
@click.option("--debug", is_flag=True, expose_value=False, is_eager=True, callback=_set_debug,
              help="Show tracebacks for internal errors.")
def cli():
    """Bake image-based lighting data and check what it looks like.

    \b
    iblbake sh ENV -o sh.json       spherical-harmonic irradiance coefficients
    iblbake mips ENV --cache DIR    radiance chain, GGX-prefiltered chain, DFG table
    iblbake render SCENE -o out.png render a scene YAML (see render --help-schema)
    iblbake devices                 OpenCL devices and which one is used
    """


@cli.command()
@common_options
def devices(quiet, as_json):
    """List OpenCL devices, whether each builds and runs a probe kernel, and which is used."""
    from iblbake.device import runtime as cl

    con = Console(quiet, as_json)
    devs, errors, chosen = cl.probe_all()
    summary = {
        "devices": [{"index": d.index, "platform": d.platform, "name": d.name, "type": d.kind,
                     "works": d.ok, "probe": d.reason, "probe_s": round(d.probe_s, 4),
                     "selected": chosen is d} for d in devs],
        "platform_errors": errors,
        "selected": chosen.label if chosen else None,
    }
    lines = []
    for d in devs:
        mark = "*" if chosen is d else " "
        lines.append(f"{mark} {d.index}  {d.kind:5s} {d.name} [{d.platform}]: "
                     f"{'works' if d.ok else 'FAILS'} ({d.reason})")
    lines += [f"  platform error: {e}" for e in errors]
    lines.append(f"selected: {chosen.label}" if chosen else "selected: none")
    con.result(summary, "\n".join(lines))
    if chosen is None:
        raise IblbakeError(f"no working OpenCL device; {cl.FIX_HINT}")


def _check_overwrite(output: str, force: bool, source: str):
    """sh replaces its own earlier documents (Makefile reruns) but nothing else unless --force,
    and never its input."""
    from iblbake.bake import sh as shbake

    out = os.path.realpath(output)
    if os.path.exists(source) and out == os.path.realpath(source):
        raise IblbakeError(f"-o {output}: is the input panorama; choose another output path")
    if force or not os.path.exists(out):
        return
    try:
        with open(out, "rb") as f:
            ours = json.loads(f.read(1 << 22)).get("format") == shbake.FORMAT
    except (OSError, ValueError, AttributeError):
        ours = False
    if not ours:
        raise IblbakeError(f"{output}: exists and is not an iblbake SH document; pass --force to "
                           f"overwrite it")


@cli.command("sh")
@click.argument("env", metavar="ENV")
@click.option("--output", "-o", type=click.Path(dir_okay=False), default=None,
              help="Write the JSON document here (atomically). Without it, nothing is written. An "
                   "existing iblbake SH document is replaced; any other existing file needs --force.")
@click.option("--force", "-f", is_flag=True, help="Overwrite --output even if it is not an iblbake SH document.")
@click.option("--bands", type=click.IntRange(1, 16), default=3, show_default=True,
              help="Number of SH bands (l = 0..bands-1; 3 gives the classic 9 coefficients).")
@click.option("--window", type=click.Choice(["none", "hann", "lanczos"]), default="none", show_default=True,
              help="Ringing reduction applied per band: hann w_l=(1+cos(pi l/bands))/2, "
                   "lanczos w_l=sinc(l/bands). Reduces negative lobes around bright suns.")
@click.option("--backend", type=click.Choice(["opencl", "numpy"]), default="opencl", show_default=True,
              help="opencl: the reduction kernel; numpy: the float64 per-texel reference.")
@click.option("--rotate-y", type=float, default=0.0, show_default=True, callback=_finite, metavar="DEG",
              help="Rotate the panorama about +y by DEG degrees (+x towards -z).")
@click.option("--intensity", type=float, default=1.0, show_default=True, callback=_non_negative,
              help="Scale the panorama's radiance.")
@click.option("--glsl", is_flag=True, help="Print a GLSL function with the irradiance coefficients.")
@input_options
@device_option
@common_options
def sh_command(env, output, force, bands, window, backend, rotate_y, intensity, glsl, nonfinite, negative,
               max_pixels, device, quiet, as_json):
    """Project the panorama ENV onto spherical harmonics and bake irradiance coefficients.

    The JSON holds the basis description, the radiance coefficients L_lm, the irradiance
    coefficients E_lm = Ahat_l * L_lm (evaluate with max(0, sum E_lm Y_lm(n)); diffuse is
    albedo/pi times that), the input's size and hash, the options and timings.
    """
    from iblbake.io import images
    from iblbake.bake import sh as shbake

    con = Console(quiet, as_json)
    if output:
        from iblbake.io.atomic import check_writable
        check_writable(output)
        _check_overwrite(output, force, env)
    t_start = time.perf_counter()
    with con.stages(["reading", "projecting"], label="sh") as stage:
        t0 = time.perf_counter()
        image, info = images.read_panorama(env, max_pixels=max_pixels, nonfinite=nonfinite, negative=negative,
                                           names=POLICY_FLAGS)
        read_s = time.perf_counter() - t0
        stage()
        rt = None
        device_label = "numpy (float64, host)"
        if backend == "opencl":
            from iblbake.device import runtime as cl
            rt = cl.Runtime(device)
            device_label = rt.device_label
        coeffs, project_s = shbake.project(image, bands, backend, rt, rotate_y)
        stage()
    for w in info.warnings:
        con.warn(w)
    coeffs = coeffs * intensity
    options = {"bands": bands, "window": window, "backend": backend, "rotate_y_deg": rotate_y,
               "intensity": intensity, "nonfinite": nonfinite, "negative": negative}
    timings = {"read_s": round(read_s, 6), "project_s": round(project_s, 6)}
    doc = shbake.document(coeffs, bands=bands, window=window, info=info, options=options,
                          device=device_label, timings=timings)
    doc["elapsed_s"] = round(time.perf_counter() - t_start, 6)
    if output:
        from iblbake.io.atomic import write_json
        write_json(output, doc)
    if glsl:
        click.echo(shbake.glsl_snippet(doc), nl=False)
    summary = {k: doc[k] for k in ("format", "format_version", "bands", "window", "irradiance", "device",
                                   "timings", "elapsed_s")}
    summary["input"] = {k: doc["input"][k] for k in ("path", "width", "height", "sha256")}
    summary["output"] = output
    dc = doc["radiance"][0]
    human = (f"{'wrote ' + output + ': ' if output else ''}{bands * bands} SH coefficients of "
             f"{info.path} ({info.width}x{info.height}) in {doc['elapsed_s']:.3f} s on {device_label}; "
             f"mean radiance {[round(c / (2 * math.sqrt(math.pi)), 5) for c in dc]}")
    if info.negative and negative == "keep":
        human += f"; {info.negative} tiny negative values kept (min {info.negative_min:.3g})"
    if glsl and not as_json:
        if not quiet:
            click.echo(human, err=True)
    else:
        con.result(summary, human)


@cli.command("mips")
@click.argument("env", metavar="ENV")
@click.option("--cache", "cache_dir", type=click.Path(file_okay=False), default=None,
              help="Cache folder; entries go to CACHE/<key>/ with a manifest.json. "
                   "Default: $IBLBAKE_CACHE, else ./iblbake-cache.")
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
@click.option("--lod-bias", type=float, default=1.0, show_default=True, callback=_finite,
              help="Added to the filtered-importance-sampling level (Krivanek and Colbert use 1).")
@click.option("--no-fis", is_flag=True, help="Plain importance sampling: every sample reads level 0.")
@click.option("--convolve-budget", type=float, default=None, callback=_non_negative,
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
@click.option("--backend", type=click.Choice(["opencl", "numpy"]), default="opencl", show_default=True,
              help="opencl: the kernels; numpy: their float64 twins (slow; small sizes).")
@input_options
@device_option
@common_options
def mips_command(env, cache_dir, layout, size, levels, min_size, method, samples, lod_bias, no_fis,
                 convolve_budget, dfg_size, dfg_samples, dfg_multiscatter, only, backend, nonfinite, negative,
                 max_pixels, device, quiet, as_json):
    """Bake the radiance mip chain, the GGX-prefiltered chain and the DFG table of ENV into a
    content-addressed EXR cache. A second run with the same inputs does no work ("cached")."""
    from pathlib import Path

    from iblbake.bake import cache
    from iblbake.io import images
    from iblbake.bake import layouts
    from iblbake.bake import mips as mipsbake

    con = Console(quiet, as_json)
    parts = {"radiance", "prefiltered", "dfg"} if "all" in only else set(only)
    t_start = time.perf_counter()
    root = Path(cache_dir) if cache_dir else cache.default_root()
    from iblbake.io.atomic import check_writable
    check_writable(root / "manifest.json", "cache", shown=root)
    baker = mipsbake.Baker(backend, device)
    report = {}
    summary = {"cache": str(root), "device": baker.device_label, "entries": report}
    if parts & {"radiance", "prefiltered"}:
        image, info = images.read_panorama(env, max_pixels=max_pixels, nonfinite=nonfinite, negative=negative,
                                           names=POLICY_FLAGS)
        for w in info.warnings:
            con.warn(w)
        policies = {"nonfinite": nonfinite, "negative": negative}
        if "prefiltered" in parts:
            opts = mipsbake.PrefilterOptions(layout, size, levels, min_size, method, samples, lod_bias,
                                             not no_fis, convolve_budget).resolved(info.height)
            # an impossible plan (--method spectral on a too sharp level) fails before any bake
            mipsbake.plan_methods(layouts.radiance_chain_sizes(info.width, info.height),
                                  {**opts, "convolve_budget": baker.convolve_budget(opts)}, "--method")
        t0 = time.perf_counter()
        manifest, cached, chain = mipsbake.bake_radiance(baker, image, info, root, policies, warn=con.warn)
        report["radiance"] = {"path": str(root / manifest["key"]), "cached": cached,
                              "seconds": round(time.perf_counter() - t0, 4), "levels": len(manifest["files"])}
        if "prefiltered" in parts:
            state = {"chain": chain}

            def chain_levels():
                if state["chain"] is None:
                    state["chain"] = mipsbake.load_chain(root, manifest)
                return state["chain"]

            levels_named = [f"level {k} (r = {r:.3g})" for k, r in enumerate(opts["roughness"])]
            with con.stages(levels_named, label="prefiltering") as step:
                t0 = time.perf_counter()
                pm, pcached = mipsbake.bake_prefiltered(baker, chain_levels, info, root, policies, opts,
                                                        warn=con.warn, progress=step)
            report["prefiltered"] = {"path": str(root / pm["key"]), "cached": pcached,
                                     "seconds": round(time.perf_counter() - t0, 4), "layout": layout,
                                     "sizes": opts["sizes"], "roughness": opts["roughness"],
                                     "methods": [f["method"] for f in pm["files"]]}
    if "dfg" in parts:
        t0 = time.perf_counter()
        dm, dcached = mipsbake.bake_dfg(baker, root, dfg_size, dfg_samples, dfg_multiscatter, warn=con.warn)
        report["dfg"] = {"path": str(root / dm["key"]), "cached": dcached,
                         "seconds": round(time.perf_counter() - t0, 4)}
    summary["elapsed_s"] = round(time.perf_counter() - t_start, 4)
    lines = [f"{kind}: {'cached' if e['cached'] else 'baked'} {e['path']} ({e['seconds']:.3f} s)"
             for kind, e in report.items()]
    lines.append(f"done in {summary['elapsed_s']:.3f} s on {baker.device_label}")
    con.result(summary, "\n".join(lines))


def _help_schema(ctx, param, value):
    if value and not ctx.resilient_parsing:
        from iblbake.scene.load import schema_text
        click.echo(schema_text(), nl=False)
        ctx.exit(0)


@cli.command("render")
@click.argument("scene_path", metavar="SCENE", required=False)
@click.option("--output", "-o", "outputs", multiple=True, type=click.Path(dir_okay=False),
              help="Frame path (.png tone-mapped, .exr linear); repeatable. Replaces output.frame of the "
                   "scene. Existing files are overwritten (atomically).")
@click.option("--set", "overrides", multiple=True, metavar="KEY.PATH=VALUE",
              help="Override a scene value, e.g. --set effects.samples=40 --set materials.gold.roughness=0.3 "
                   "--set objects.0.sphere.radius=2 (repeatable; values parse as YAML).")
@click.option("--cache", "cache_dir", type=click.Path(file_okay=False), default=None,
              help="Bake cache folder (shared with `iblbake mips`). Default: $IBLBAKE_CACHE, else ./iblbake-cache.")
@click.option("--report", "show_report", is_flag=True,
              help="Print the effect set, every bake and pass with its time and cache hit/miss, and the device.")
@click.option("--help-schema", is_flag=True, expose_value=False, is_eager=True, callback=_help_schema,
              help="Print every scene key with its type, range and default, and exit.")
@device_option
@common_options
def render_command(scene_path, outputs, overrides, cache_dir, show_report, device, quiet, as_json):
    """Render the scene file SCENE (YAML; see --help-schema and examples/scenes/) with OpenCL.

    Only the effects the scene calls for are baked, compiled and run; --report shows which.
    """
    from iblbake import render
    from iblbake.scene import load as scene

    if scene_path is None:
        raise click.UsageError("missing SCENE (a scene YAML file; see --help-schema)")
    con = Console(quiet, as_json)
    sc = scene.load(scene_path, overrides, outputs)
    from iblbake.io.atomic import check_writable
    for p in render.output_paths(sc):
        check_writable(p)
    with con.stages(["reference samples"] * 100, label="render") if (
            "reference" in render.plan(sc).pass_names and con.interactive) else contextlib.nullcontext(None) as step:
        last = [0]

        def progress(frac):
            if step is None:
                return
            k = int(frac * 100)
            while last[0] < k:
                step()
                last[0] += 1

        frame = render.render(sc, device=device, cache_root=cache_dir, warn=con.warn, progress=progress)
    written = render.write_outputs(frame, sc)
    rep = frame.report
    for note in rep["effects"]["notes"]:
        con.note(f"iblbake: {note}")
    summary = {**rep, "scene": sc.source, "outputs": written}
    lines = []
    if show_report:
        e = rep["effects"]
        lines.append(f"device: {rep['device']}")
        lines.append(f"effects: diffuse={e['diffuse']} specular={e['specular']} background={e['background']}"
                     f"{' emissive' if e['emissive'] else ''}")
        for name, defs in e["defines"].items():
            lines.append(f"defines {name}: " + (" ".join(f"{k}={v}" for k, v in defs.items()) or "-"))
        for b in rep["bakes"]:
            extra = " ".join(f"{k}={v}" for k, v in b.items() if k not in ("name", "seconds", "cached", "entry",
                                                                             "meshes"))
            lines.append(f"bake  {b['name']:<16} {b['seconds']:8.3f} s  {'hit ' if b['cached'] else 'miss'}  {extra}")
        for p in rep["passes"]:
            extra = " ".join(f"{k}={v}" for k, v in p.items() if k not in ("name", "seconds"))
            lines.append(f"pass  {p['name']:<16} {p['seconds']:8.3f} s        {extra}")
        for b in rep["kernel_builds"]:
            lines.append(f"build {b['kernel']:<16} {b['seconds']:8.3f} s")
    w, h = rep["resolution"]
    lines.append(f"{'wrote ' + ', '.join(written) if written else 'rendered'} ({w}x{h}, {rep['spp']} spp) "
                 f"in {rep['elapsed_s']:.3f} s on {rep['device']}")
    con.result(summary, "\n".join(lines))


def main():
    """Run the CLI (iblbake.entry.main is the console script)."""
    from iblbake.entry import loaded
    loaded()
    try:
        rv = cli.main(standalone_mode=False, prog_name="iblbake")
    except IblbakeError as e:
        click.echo(f"Error: {e}", err=True)
        sys.exit(e.exit_code)
    except click.ClickException as e:
        e.show()
        sys.exit(e.exit_code)
    except click.exceptions.Abort:
        click.echo("iblbake: interrupted", err=True)
        sys.exit(130)
    except KeyboardInterrupt:
        click.echo("iblbake: interrupted", err=True)
        sys.exit(130)
    sys.exit(rv if isinstance(rv, int) else 0)


if __name__ == "__main__":
    main()
