"""Exceptions shared by every layer.

Library code raises these (or ``ValueError``/``OSError``); the CLI turns them
into one-line messages (:func:`first_line`).
"""


class WbcgradeError(Exception):
    """A failure a user can act on (bad file, bad option, unsafe computation)."""


class InputError(WbcgradeError, ValueError):
    """An input file or array is unusable (unreadable, corrupt, wrong shape).

    ``fields``: settings the message names as the library does (``"recursive"``,
    ``"spaces.working"``), each once, in a hint; the CLI writes them as their flags.
    ``path``: the file or folder the message starts with (``"PATH: ..."``), which the
    CLI never rewrites.
    """

    def __init__(self, *args, fields: tuple[str, ...] = (), path: object = None) -> None:
        super().__init__(*args)
        self.fields = tuple(fields)
        self.path = None if path is None else str(path)


class NumericalError(WbcgradeError, FloatingPointError):
    """A computation could not be carried out safely in the requested precision."""


class OptionError(InputError):
    """A setting (a command-line option) has an unusable value.

    ``option`` names the setting as the library does (a field such as
    ``"transfer.bins"``, or a parameter such as ``"lut_size"``), and the
    message names it the same way; ``also`` names other settings the message
    mentions. The CLI writes each as the flag that sets it (``--bins``) and
    reports the error as a usage error (exit status 2), like click's own.
    ``path``: the file or folder the message starts with (``"PATH: ..."``),
    which the CLI never rewrites (a folder may be called ``codec``).
    """

    def __init__(self, message: str, option: str, also: tuple[str, ...] = (),
                 path: object = None) -> None:
        super().__init__(message, path=path)
        self.option = option
        self.also = tuple(also)


class Terminated(KeyboardInterrupt):
    """The process was asked to end (SIGTERM, SIGHUP): raised in the main thread by the
    CLI's signal handler, so that clean-up runs as for Ctrl-C (temporary files removed,
    ffmpeg and workers stopped). ``signum`` is the signal's number."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


class ConvergenceWarning(UserWarning):
    """An iterative solve stopped at its iteration limit before reaching its tolerance.

    The result is still returned (its ``converged`` flag is False); raise the
    limit, loosen the tolerance, or silence this with ``warn=False``.
    """


def first_line(text: object, default: str = "unknown error") -> str:
    """The first non-empty line of a message (an exception, a library's error text).

    >>> first_line("disk full\\n  at write()"), first_line("", "no reason")
    ('disk full', 'no reason')
    """
    if isinstance(text, BaseException) and not str(text).strip():
        return type(text).__name__
    lines = [line.strip() for line in str(text).strip().splitlines() if line.strip()]
    return lines[0] if lines else default
