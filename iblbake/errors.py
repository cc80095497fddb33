"""Errors the CLI turns into one-line messages (no traceback unless --debug)."""

import click


class IblbakeError(click.ClickException):
    """A failure the user can act on: the message names the file/key/value and the fix."""

    exit_code = 1


class InputError(IblbakeError):
    """A bad input file or value."""


class DeviceError(IblbakeError):
    """No usable OpenCL device, or a kernel that failed to build or run."""

    exit_code = 3
