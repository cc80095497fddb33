"""The `iblbake` command line: thin click commands that parse, call the library and print; one
module per command, loaded only when that command runs (a Makefile calls `iblbake sh` once
per file: it should not pay for the others), shared options in options.py. The only place that
knows click.

Errors the user can act on are the library's IblbakeError (iblbake.errors, plain exceptions): printed
here as one line, exit != 0. Anything else is an internal error: one line too, unless --debug
asks for the traceback. Heavy modules (pyopencl, OpenImageIO, trimesh) are imported inside the
commands that use them.
"""

from __future__ import annotations

import sys

import click

from iblbake import __version__
import importlib

from iblbake.cli.options import _DEBUG, _set_debug
from iblbake.errors import IblbakeError


# command name -> (module, attribute): imported on first use
COMMANDS = {
    "accuracy": ("accuracy", "accuracy_command"), "basis": ("basis", "basis_command"), "cache": ("cache", "cache_group"),
    "compare": ("compare", "compare_command"),
    "deps": ("render", "deps_command"), "devices": ("devices", "devices"),
    "export-gltf": ("export_gltf", "export_gltf_command"), "lightmap": ("lightmap", "lightmap_command"),
    "mips": ("mips", "mips_command"),
    "probes": ("probes", "probes_command"), "render": ("render", "render_command"), "sh": ("sh", "sh_command"), "sheet": ("sheet", "sheet_command"),
}


class IblbakeGroup(click.Group):
    def list_commands(self, ctx):
        return sorted(COMMANDS)

    def get_command(self, ctx, name):
        if name not in COMMANDS:
            return None
        module, attr = COMMANDS[name]
        return getattr(importlib.import_module(f"iblbake.cli.{module}"), attr)

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


@click.group(cls=IblbakeGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="iblbake")
@click.option("--debug", is_flag=True, expose_value=False, is_eager=True, callback=_set_debug,
              help="Show tracebacks for internal errors.")
def cli():
    """Bake image-based lighting data and check what it looks like.

    \b
    iblbake sh ENV -o sh.json       spherical-harmonic irradiance coefficients
    iblbake basis ENV --basis zh3   another directional basis (ZH3, SG, ambient dice, Haar...)
    iblbake mips ENV --cache DIR    radiance chain, GGX-prefiltered chain, DFG table
    iblbake export-gltf ENV -o l.gltf  a glTF image-based light (EXT_lights_image_based)
    iblbake probes SCENE -o DIR/    irradiance probes (DDGI): atlases, manifest, GLSL sampler
    iblbake lightmap SCENE -o DIR/  a lightmap: atlases (EXR, KTX2), manifest, GLSL, glTF with TEXCOORD_1
    iblbake render SCENE -o out.png render a scene YAML (see render --help-schema)
    iblbake sheet SCENE -o s.png    a contact sheet of the scene's sweep (or --rows/--columns)
    iblbake deps SCENE              the Make rule of what rendering SCENE reads
    iblbake accuracy SCENE -o DIR/  each approximation's error against the reference, and its time
    iblbake compare A B             FLIP or RMSE between frames or sheets (per cell), for CI
    iblbake cache [prune]           the bake cache's entries; trim it to a size
    iblbake devices                 OpenCL devices and which one is used
    """


def main():
    """Run the CLI (iblbake.entry.main is the console script)."""
    from iblbake.entry import finished, loaded
    loaded()
    code = 130
    try:
        code = _run()
        finished()
    except KeyboardInterrupt:       # raised once (iblbake.entry): a second Ctrl-C is dropped
        finished()
        click.echo("iblbake: interrupted", err=True)
    sys.exit(code)


def _run() -> int:
    """The command's exit code; its errors printed as one line each."""
    try:
        rv = cli.main(standalone_mode=False, prog_name="iblbake")
    except IblbakeError as e:
        click.echo(f"Error: {e}", err=True)
        return e.exit_code
    except click.UsageError as e:     # one line, as every other error (click's own takes three)
        where = e.ctx.command_path if e.ctx else "iblbake"
        click.echo(f"Error: {e.format_message()} (try '{where} --help')", err=True)
        return e.exit_code
    except click.ClickException as e:
        e.show()
        return e.exit_code
    except click.exceptions.Abort:
        click.echo("iblbake: interrupted", err=True)
        return 130
    return rv if isinstance(rv, int) else 0
