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


class OptionError(InputError):
    """A setting (a command-line option) has an unusable value.

    ``option`` names it as the command line spells it (e.g. ``"-o/--png"``);
    the CLI reports it as a usage error (exit status 2), like click's own.
    """

    def __init__(self, message: str, option: str) -> None:
        super().__init__(message)
        self.option = option


class ConvergenceWarning(UserWarning):
    """An iterative solve stopped at its iteration limit before reaching its tolerance.

    The result is still returned (its ``converged`` flag is False); raise the
    limit, loosen the tolerance, or silence this with ``warn=False``.
    """
