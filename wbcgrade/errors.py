"""Exceptions shared by every layer.

Library code raises these (or ``ValueError``/``OSError``); the CLI turns them
into one-line messages.
"""


class WbcgradeError(Exception):
    """A failure a user can act on (bad file, bad option, unsafe computation)."""


class InputError(WbcgradeError, ValueError):
    """An input file or array is unusable (unreadable, corrupt, wrong shape)."""


class NumericalError(WbcgradeError, FloatingPointError):
    """A computation could not be carried out safely in the requested precision."""
