"""The library's errors: plain exceptions whose message is one line that names the file, key or
value and what to do. The command line (iblbake.cli) prints them and exits with `exit_code`; the
library never imports click."""


class IblbakeError(Exception):
    """A failure the user can act on: its message is one line naming the file, key or value and
    what to do; exit_code is what the command line exits with."""

    exit_code = 1


class InputError(IblbakeError):
    """A bad input file or value (a panorama, a scene, a mesh, an argument)."""


class UsageError(InputError):
    """A command-line value that does not parse (a --set or --rows spec): exit 2, as every other
    usage error."""

    exit_code = 2


class DeviceError(IblbakeError):
    """No usable OpenCL device, or a kernel that failed to build or run."""

    exit_code = 3


# the public name (iblbake.Error): every error the library raises for the user is one
Error = IblbakeError
