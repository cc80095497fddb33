"""Console-script entry point. A Ctrl-C that lands while Python is still importing the CLI
(click, numpy...) exits quietly with 130 instead of printing a traceback from inside an import;
once the CLI is loaded, Ctrl-C raises KeyboardInterrupt again, so atomic writes clean up."""

import os
import signal
import sys


def _interrupted_while_loading(signum, frame):
    sys.stderr.write("iblbake: interrupted\n")
    os._exit(130)


def quiet_startup():
    signal.signal(signal.SIGINT, _interrupted_while_loading)


def loaded():
    signal.signal(signal.SIGINT, signal.default_int_handler)


def main():
    quiet_startup()
    from iblbake.cli.main import main as cli_main
    cli_main()
