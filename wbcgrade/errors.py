"""Exceptions shared by every layer.

Library code raises these (or ``ValueError``/``OSError``); the CLI turns them
into one-line messages (:func:`first_line`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping


def named(text: str, settings: Iterable[str], name_of: Mapping[str, str] | None = None) -> str:
    """``text`` with each of ``settings`` it names as ``{setting}`` written as ``name_of``
    says (the command line: its flags), else as the setting itself.

    >>> named("raise {map.strength}", ["map.strength"])
    'raise map.strength'
    >>> named("raise {map.strength}", ["map.strength"], {"map.strength": "--strength"})
    'raise --strength'
    """
    for setting in settings:
        text = text.replace("{" + setting + "}", (name_of or {}).get(setting, setting))
    return text


class Worded(str):
    """A library text that names settings (``"raise {map.strength}"``): as a str, each is
    written as the library names it (``map.strength``); :meth:`worded` writes them as a
    caller names them (the command line: as flags, ``--strength``)."""

    template: str
    settings: tuple[str, ...]

    def __new__(cls, template: str, settings: Iterable[str] = ()) -> Worded:
        settings = tuple(settings)
        text = super().__new__(cls, named(template, settings))
        text.template, text.settings = template, settings
        return text

    def worded(self, name_of: Mapping[str, str]) -> str:
        """The text with its settings written as ``name_of`` says."""
        return named(getattr(self, "template", str(self)), getattr(self, "settings", ()),
                     name_of)


def worded_error(error: BaseException, before: str = "", after: str = "",
                 whole: bool = False) -> Worded:
    """The first line of ``error``'s message (``whole``: all of it) between ``before`` and
    ``after``, still naming the settings the message names (:meth:`Worded.worded`: the
    command line writes them as flags)."""
    template = getattr(error, "template", None)
    text = template if template is not None else str(error)
    text = text.strip() if whole and text.strip() else first_line(
        text if template is not None else error)
    return Worded(f"{before}{text}{after}", getattr(error, "settings", ()) if template else ())


def worded_text(text: str, before: str = "", after: str = "") -> Worded:
    """``text`` (a :class:`Worded` or a plain str) between ``before`` and ``after``, the
    settings it names kept."""
    template = getattr(text, "template", str(text))
    return Worded(f"{before}{template}{after}", getattr(text, "settings", ()))


class WbcgradeError(Exception):
    """A failure a user can act on (bad file, bad option, unsafe computation).

    ``fields``: settings the message names as the library does (``"recursive"``,
    ``"spaces.working"``), each written ``{recursive}`` in the message (:func:`named`);
    the CLI writes them as their flags (:meth:`worded`).
    """

    def __init__(self, *args, fields: tuple[str, ...] = ()) -> None:
        self.fields = tuple(fields)
        self.template = args[0] if args and isinstance(args[0], str) else None
        if self.template is not None:
            args = (named(self.template, self.settings), *args[1:])
        super().__init__(*args)

    @property
    def settings(self) -> tuple[str, ...]:
        """The settings the message names."""
        return self.fields

    def worded(self, name_of: Mapping[str, str]) -> str:
        """The message with the settings it names written as ``name_of`` says."""
        if getattr(self, "template", None) is None:
            return str(self)
        return named(self.template, self.settings, name_of)


class InputError(WbcgradeError, ValueError):
    """An input file or array is unusable (unreadable, corrupt, wrong shape).

    ``fields``: the settings the message names (:class:`WbcgradeError`).
    ``path``: the file or folder the message starts with (``"PATH: ..."``).
    """

    def __init__(self, *args, fields: tuple[str, ...] = (), path: object = None) -> None:
        super().__init__(*args, fields=fields)
        self.path = None if path is None else str(path)


class NumericalError(WbcgradeError, FloatingPointError):
    """A computation could not be carried out safely in the requested precision."""


class OptionError(InputError):
    """A setting (a command-line option) has an unusable value.

    ``option`` names the setting as the library does (a field such as
    ``"transfer.bins"``, or a parameter such as ``"lut_size"``), and the
    message names it the same way, in braces (``"{transfer.bins} must be ..."``,
    :func:`named`); ``also`` names other settings the message mentions. The CLI
    writes each as the flag that sets it (``--bins``, :meth:`worded`) and reports
    the error as a usage error (exit status 2), like click's own.
    ``path``: the file or folder the message starts with (``"PATH: ..."``).
    """

    def __init__(self, message: str, option: str, also: tuple[str, ...] = (),
                 path: object = None) -> None:
        self.option = option
        self.also = tuple(also)
        super().__init__(message, path=path)

    @property
    def settings(self) -> tuple[str, ...]:
        return (self.option, *self.also, *self.fields)


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
