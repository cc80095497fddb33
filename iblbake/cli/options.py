"""What every command shares: the console (notes, warnings, progress, --json), the common
options (--json, --quiet, --debug, --device, the panorama read policies) and validating callbacks."""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys

import click

_DEBUG = {"on": bool(os.environ.get("IBLBAKE_DEBUG"))}


def _set_debug(ctx, param, value):
    if value:
        _DEBUG["on"] = True
    return value


class Console:
    """Where a command's human output goes: notes and warnings on stderr, silenced by --quiet;
    machine-readable JSON on stdout with --json."""

    def __init__(self, quiet: bool, as_json: bool):
        self.quiet, self.as_json = quiet, as_json
        self._warned: set = set()

    def note(self, text: str):
        if not self.quiet:
            click.echo(text, err=True)

    def warn(self, text: str):
        """Once per message (a sheet's cells read the same panorama)."""
        if not self.quiet and text not in self._warned:
            self._warned.add(text)
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
                        help="OpenCL device: 'gpu', 'cpu', 'gpu:N' / 'cpu:N' (the N-th of that kind), "
                             "'P:D' (platform:device index) or part of its name. Default: $IBLBAKE_DEVICE, else the first working GPU, else CPU.")(f)


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
    f = click.option("--input-transfer", "transfer", type=click.Choice(["auto", "srgb", "linear"]), default="auto",
                     show_default=True,
                     help="How texels decode to linear: auto (an 8/16-bit PNG or JPEG from sRGB, or the linear "
                          "or gamma it declares; float images as stored), srgb, or linear.")(f)
    f = click.option("--input-layout", "input_layout", default="auto", show_default=True,
                     type=click.Choice(["auto", "equirect", "hcross", "vcross", "hstrip", "vstrip", "faces", "ktx2"]),
                     help="What ENV holds: an equirect panorama, a cube map as a horizontal or vertical cross, "
                          "a strip of six faces (+X -X +Y -Y +Z -Z), six face files (a path with {face}: px nx "
                          "py ny pz nz) or a KTX2 cube map; auto goes by {face}, .ktx2, then the aspect ratio. "
                          "Cube maps are resampled to an equirect panorama.")(f)
    f = click.option("--primaries", type=click.Choice(["keep", "convert"]), default="keep", show_default=True,
                     help="An EXR declaring chromaticities other than Rec.709: keep its values as stored, or "
                          "convert them to Rec.709/D65 (Bradford adaptation of the white).")(f)
    return f


# the read policies as this command line names them (the library's messages quote these)
POLICY_FLAGS = {"max_pixels": "--max-pixels", "nonfinite": "--nonfinite", "negative": "--negative",
                "transfer": "--input-transfer", "primaries": "--primaries", "layout": "--input-layout"}


def finite(ctx, param, value):
    if value is not None and not math.isfinite(value):
        raise click.BadParameter(f"{value} is not a finite number")
    return value


def non_negative(ctx, param, value):
    value = finite(ctx, param, value)
    if value is not None and value < 0:
        raise click.BadParameter(f"{value} is negative; give a value >= 0")
    return value


def _set_max_texture_pixels(ctx, param, value):
    if value is not None:     # the library (and worker processes) read it from the environment
        os.environ["IBLBAKE_MAX_TEXTURE_PIXELS"] = str(value)
    return value


def max_texture_pixels_option(f):
    return click.option("--max-texture-pixels", type=click.IntRange(min=1), default=None, expose_value=False,
                        callback=_set_max_texture_pixels,
                        help="Refuse larger material textures before decoding them. Default: "
                             "$IBLBAKE_MAX_TEXTURE_PIXELS or 8192*8192.")(f)


def depfile_option(f):
    return click.option("--depfile", type=click.Path(dir_okay=False), default=None, metavar="FILE",
                        help="Also write a Make dependency file (as gcc -MD -MF): the outputs depend on "
                             "every file read. Use with `-include *.d` in a Makefile.")(f)


def input_files_of(env: str) -> list:
    """The files an ENV argument reads (six for a {face} path), for depfiles."""
    from iblbake.bake.inputs import files_of
    return files_of(env)
