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
    machine-readable JSON on stdout with --json, its `warnings` every warning said (or silenced)."""

    def __init__(self, quiet: bool, as_json: bool):
        self.quiet, self.as_json = quiet, as_json
        self._warned: dict = {}          # each warning once, in the order said
        self._bar = False                # a progress bar holds the terminal's last line

    def note(self, text: str):
        if not self.quiet:
            click.echo(text, err=True)

    def warn(self, text: str):
        """Once per message (a sheet's cells read the same panorama)."""
        if text in self._warned:
            return
        self._warned[text] = None
        if not self.quiet:
            # on its own line: the bar's line is cleared first and redrawn at its next step
            click.echo(("\r\x1b[2K" if self._bar else "") + f"iblbake: warning: {text}", err=True)

    @property
    def interactive(self) -> bool:
        return not self.quiet and sys.stderr.isatty() and not os.environ.get("CI")

    @contextlib.contextmanager
    def stages(self, names, label: str, bound_first: bool = False):
        """A progress bar over named stages on an interactive terminal; silent otherwise.
        Yields a function that marks the current stage done. bound_first: until a second burst
        of steps, the time left is bounded from the bar's start (fraction(): a long bake's first
        launch says its scale)."""
        if not self.interactive:
            quiet = lambda _=1: None
            quiet.relabel = lambda _text: None
            yield quiet
            return
        import time

        names = list(names)
        n = len(names)
        # The time left is estimated from the stages after the first: the first pays the kernel
        # builds and the device's first-launch specialisation (click's own ETA counted it, and
        # read 2 min 49 s left of a 6 s render); with bound_first, "at most" the first's rate until then.
        with click.progressbar(length=n, label=label, file=sys.stderr, show_eta=False,
                               item_show_func=lambda i: i) as bar:
            done, start = [0], time.perf_counter()
            anchor = []          # (time, stages done) at the end of the first burst of steps

            def step(k=1):   # k stages done (callers that report progress(1): one)
                done[0] += k
                now = time.perf_counter()
                if not anchor or (len(anchor) == 2 and now - anchor[0] < 0.01):
                    anchor[:] = [now, done[0]]          # steps a batch reports at once
                elif len(anchor) == 2:
                    anchor.append(True)
                item = names[done[0]] if done[0] < n else "done"
                if len(anchor) == 3 and done[0] < n:
                    left = (now - anchor[0]) / (done[0] - anchor[1]) * (n - done[0])
                    item += f", {_duration(left)} left"
                elif bound_first and done[0] < n:
                    item += f", at most {_duration((now - start) / done[0] * (n - done[0]))} left"
                bar.update(k, item)
            def relabel(text):       # the work's size, once known (the bar's label)
                bar.label = f"{label}: {text}"
                bar.render_progress()
            step.relabel = relabel
            self._bar = True
            try:
                bar.update(0, names[0])
                yield step
            finally:
                self._bar = False

    @contextlib.contextmanager
    def fraction(self, label: str, name: str):
        """stages() over 1000 steps of one named kind of work, fed by the fraction done (0 to 1):
        yields progress(frac), for the library's progress callbacks."""
        with self.stages([name] * 1000, label, bound_first=True) as step:
            done = [0]

            def progress(frac):
                now = min(int(frac * 1000), 1000)
                if now > done[0]:
                    step(now - done[0])
                    done[0] = now

            def describe(text):
                """The work's size, said up front by the library (render/paths/trace.py describe): a note on
                stderr (before the bar's line) and the bar's label."""
                self.note(("\r\x1b[2K" if self._bar else "") + f"iblbake: {text}")
                step.relabel(text)
            progress.describe = describe
            yield progress

    def result(self, summary: dict, human: str):
        if self.as_json:
            click.echo(json_text({**summary, "warnings": list(self._warned)}))
        elif not self.quiet:
            click.echo(human)


def _shown(value):
    """value with every str made valid Unicode: a file name that is not UTF-8 reaches Python with
    lone surrogates (os.fsdecode), which json.dumps writes as '\\udcff' escapes that strict
    readers refuse and jq shows as U+FFFD; its undecodable bytes are written as '\\xff' instead,
    as Python's own backslashreplace shows them."""
    if isinstance(value, str):
        return value.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    if isinstance(value, dict):
        return {_shown(k): _shown(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_shown(v) for v in value]
    return value


def json_text(summary: dict, indent: int = 2) -> str:
    """A command's --json document: strict JSON (no NaN) of valid Unicode."""
    return json.dumps(_shown(summary), indent=indent, allow_nan=False)


def _duration(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60} min {seconds % 60:02d} s" if seconds >= 60 else f"{seconds} s"


def extracted_said(n: int, how: str, kept_in: str, why: str = "") -> str:
    """'; N lights extracted from the panorama[HOW] (WHYenvironment.sun: none keeps them in KEPT_IN)':
    what render and probes say of the lights `environment.sun` took out of the panorama, in one
    wording; '' for none."""
    if not n:
        return ""
    s, them = ("s", "them") if n != 1 else ("", "it")
    return f"; {n} light{s} extracted from the panorama{how} ({why}environment.sun: none keeps {them} in {kept_in})"


def written_lights_said(lights: list, written: str, kept_in: str) -> str:
    """What probes and lightmap say of the lights a bake's manifest (`written`) lists that were
    extracted from the panorama: an engine cannot know of them but from it, and draws them per
    pixel."""
    n = sum(not lt["source"].startswith("lights.") for lt in lights)
    return extracted_said(n, f", to draw per pixel: {written}'s lights", kept_in)


def common_options(f):
    """--json, --quiet, --debug, shared by every command."""
    f = click.option("--debug", is_flag=True, expose_value=False, is_eager=True, callback=_set_debug,
                     help="Show tracebacks for internal errors.")(f)
    f = click.option("--quiet", "-q", is_flag=True, help="Print nothing but errors.")(f)
    f = click.option("--json", "as_json", is_flag=True, help="Print a machine-readable JSON summary on stdout.")(f)
    return f


def device_option(f):
    return click.option("--device", "-d", default=None, metavar="SPEC", show_default=False,
                        help="OpenCL device: 'gpu', 'cpu', 'gpu:N' / 'cpu:N' (the N-th of that kind), 'pocl', "
                             "'intel-cpu' (Intel's CPU runtime: pip install 'iblbake[intel-cpu]'), "
                             "'P:D' (platform:device index) or part of its name. Default: $IBLBAKE_DEVICE, else the "
                             "first working GPU, else a CPU (PoCL before Intel's runtime).")(f)


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
    f = click.option("--primaries", type=click.Choice(["auto", "keep", "convert"]), default="auto", show_default=True,
                     help="An EXR declaring chromaticities other than Rec.709: keep its values as stored and say "
                          "so (auto), keep them silently (keep), or convert them to Rec.709/D65 (Bradford "
                          "adaptation of the white).")(f)
    return f


# the read policies as this command line names them (the library's messages quote these)
POLICY_FLAGS = {"max_pixels": "--max-pixels", "nonfinite": "--nonfinite", "negative": "--negative",
                "transfer": "--input-transfer", "primaries": "--primaries", "layout": "--input-layout"}
# the API's arguments as this command line names them: its `names=` (the API's messages say the
# arguments' own names by default)
API_FLAGS = {**POLICY_FLAGS, "layout_hint": "--input-layout (environment.layout)", "device": "--device",
             "overrides": "--set", "max_side": "--max-side", "max_samples": "--max-samples", "bounces": "--bounces",
             "visibility": "--no-visibility", "ladder": "--ladder", "profile_paths": "--profile-paths"}


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


def _set_max_pixels(ctx, param, value):
    if value is not None:     # the library (and worker processes) read it from the environment
        os.environ["IBLBAKE_MAX_PIXELS"] = str(value)
    return value


def max_pixels_option(f):
    """--max-pixels for the commands that read a scene's panorama (sh, mips and export-gltf take
    it with their input options)."""
    return click.option("--max-pixels", type=click.IntRange(min=1), default=None, expose_value=False,
                        callback=_set_max_pixels,
                        help="Refuse larger panoramas before decoding them. Default: $IBLBAKE_MAX_PIXELS "
                             "or 8192*8192.")(f)


def _set_allow_outside(ctx, param, value):
    if value:     # the library (and worker processes) read it from the environment
        os.environ["IBLBAKE_ALLOW_OUTSIDE"] = "1"
    return value


def allow_outside_option(f):
    """--allow-outside for the commands that read a scene (iblbake/io/confine.py)."""
    return click.option("--allow-outside", is_flag=True, expose_value=False, callback=_set_allow_outside,
                        help="Let the scene write its outputs outside its folder, and its glTF files read "
                             "buffers and images outside theirs (absolute paths, .., links). Default: "
                             "$IBLBAKE_ALLOW_OUTSIDE, else refused.")(f)


def max_texture_pixels_option(f):
    return click.option("--max-texture-pixels", type=click.IntRange(min=1), default=None, expose_value=False,
                        callback=_set_max_texture_pixels,
                        help="Refuse larger material textures before decoding them. Default: "
                             "$IBLBAKE_MAX_TEXTURE_PIXELS or 8192*8192.")(f)


def cache_option(what: str = "Bake cache folder"):
    """--cache: the bake store's folder (iblbake.bake.cache), `what` its help's first words."""
    return click.option("--cache", "cache_dir", type=click.Path(file_okay=False), default=None,
                        help=f"{what}. Default: $IBLBAKE_CACHE, else the per-user cache folder.")


def force_option(f):
    """--force: the one overwrite rule (iblbake.io.guard.refuse_foreign) let through."""
    return click.option("--force", "-f", is_flag=True,
                        help="Overwrite existing outputs even where they are not files iblbake wrote "
                             "(iblbake's own earlier outputs are replaced without it).")(f)


def scene_options(f):
    """What every command that loads a scene takes, in one order: --force, --device, --max-pixels,
    --allow-outside, --max-texture-pixels and the common options (render, probes, lightmap,
    accuracy, sheet)."""
    for option in (common_options, max_texture_pixels_option, allow_outside_option, max_pixels_option,
                   device_option, force_option):
        f = option(f)
    return f


def write_texts(results, outputs, fmt: str) -> list:
    """`sh` and `basis`: each panorama's result (summary, human line, text) written to its output
    (atomically) or, without one, its text printed where the format is an engine's; returns
    (summary, human line) with the line saying what was written."""
    from iblbake.io.atomic import write_text
    done = []
    for (summary, human, text), out in zip(results, outputs):
        summary["output"] = out
        if out:
            write_text(out, text)
            human = f"wrote {out}: {human}"
        elif fmt != "iblbake":
            click.echo(text, nl=False)
        done.append((summary, human))
    return done


def report_results(con, results, fmt: str, printed_text: bool, as_json: bool, quiet: bool) -> None:
    """`sh` and `basis`: one panorama's summary, or every one's under "panoramas"; where an
    engine's text went to stdout (printed_text), the human line goes to stderr instead."""
    if len(results) == 1:
        summary, human = results[0]
        if fmt != "iblbake" and printed_text and not as_json:
            if not quiet:
                click.echo(human, err=True)
        else:
            con.result(summary, human)
    else:
        con.result({"panoramas": [s for s, _ in results]}, "\n".join(h for _, h in results))


def refuse_foreign(writes, force: bool, first_lines=()) -> None:
    """Every output that exists and is not iblbake's is refused unless --force (before any work)."""
    from iblbake.io.guard import refuse_foreign as refuse
    refuse([(flag, p) for flag, p in writes if p], force, first_lines)


def depfile_option(f):
    return click.option("--depfile", type=click.Path(dir_okay=False), default=None, metavar="FILE",
                        help="Also write a Make dependency file (as gcc -MD -MF): the outputs depend on "
                             "every file read. Use with `-include *.d` in a Makefile.")(f)


def input_files_of(env: str) -> list:
    """The files an ENV argument reads (six for a {face} path), for depfiles."""
    from iblbake.bake.inputs import files_of
    return files_of(env)


def panorama_reads(envs) -> list:
    """(what, path) of every file the ENV arguments read, for the overwrite guard."""
    return [("the input panorama", f) for env in envs for f in input_files_of(str(env))]


def check_inputs_exist(envs) -> None:
    """Every ENV names a file, checked before any work (so `sh A missing -o DIR/` bakes nothing)."""
    import os

    from iblbake.errors import InputError
    for f in (f for env in envs for f in input_files_of(str(env))):
        if os.path.isdir(f):
            raise InputError(f"{f}: is a folder, not a panorama file")
        if not os.path.exists(f):
            raise InputError(f"{f}: no such file")


def check_suffix(path, suffixes, flag: str, what: str) -> None:
    """An output's extension says what it holds: refuse `-o x.xyz` before any work."""
    from pathlib import Path
    if Path(str(path)).suffix.lower() not in suffixes:
        raise click.BadParameter(f"{path}: {what} is written as {' or '.join(suffixes)}; give such a path",
                                 param_hint=flag)
