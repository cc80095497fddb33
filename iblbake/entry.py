"""Console-script entry point and Ctrl-C handling.

A Ctrl-C that lands while Python is still importing the CLI (click, numpy...) exits quietly with
130 instead of printing a traceback from inside an import. Once the CLI is loaded, Ctrl-C raises
KeyboardInterrupt, so atomic writes clean up, but never inside an import: an exception raised
while an extension module initialises can abort the process (nanobind, which pyopencl and
OpenImageIO are built with, calls abort() when creating one of its enums fails, and the enum is
created by calling Python code that a Ctrl-C can interrupt). Such a Ctrl-C is held back and raised
as soon as the imports on the stack have finished. One Ctrl-C is raised once: a second one while the
first unwinds (atomic writes removing their temporary files), or one after the work has finished
(`finished`: the exit code and the outputs are settled, Python is shutting down), is dropped
rather than printed as a traceback from wherever it landed."""

import atexit
import os
import _signal as signal   # builtin: the signal module imports enum (a millisecond before Ctrl-C is handled)
import sys

_RETRY_S = 0.02
_STATE = {"raised": False, "finished": False}


def _interrupted_while_loading(signum, frame):
    sys.stderr.write("iblbake: interrupted\n")
    os._exit(130)


def _importing(frame) -> bool:
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            return True
        frame = frame.f_back
    return False


def _interrupt(signum, frame):
    """SIGINT, and SIGALRM while one is held back: raise it unless an import is running."""
    if _STATE["raised"] or _STATE["finished"]:
        return
    if _importing(frame):
        if not sys.is_finalizing():
            signal.setitimer(signal.ITIMER_REAL, _RETRY_S)
        return
    _STATE["raised"] = True
    raise KeyboardInterrupt


def _drop_held_interrupt():
    """The run ended while a Ctrl-C was held back: its work is done, so let it exit as it would
    have. An alarm left armed would fire after Python restores SIGALRM's default action at exit
    and kill the process with signal 14 (seen in the kill loop when mips hit the cache)."""
    signal.setitimer(signal.ITIMER_REAL, 0)


def quiet_startup():
    signal.signal(signal.SIGINT, _interrupted_while_loading)


def loaded():
    atexit.register(_drop_held_interrupt)     # registered first, so it runs last
    signal.signal(signal.SIGALRM, _interrupt)
    signal.signal(signal.SIGINT, _interrupt)


def finished():
    """The command's work is over (its exit code is known): a Ctrl-C from here on is dropped."""
    _STATE["finished"] = True
    signal.setitimer(signal.ITIMER_REAL, 0)


def main():
    quiet_startup()
    from iblbake.cli.main import main as cli_main
    cli_main()
