"""Errors the user can fix: the CLI prints them as one line, without a traceback."""


class UserError(Exception):
    """A bad file, a silent port, a bad option: something the user can act on."""
