"""The one exception type for errors a user can cause."""

from __future__ import annotations


class FacegenError(Exception):
    """A problem with the user's input or environment.

    The message says what is wrong and how to fix it, in one line, in the library's terms: it names no
    command-line flag. `param` names the library parameter (or parameters) the problem is about, e.g.
    "text", "bundle" or ("lip_weight", "upper_weight"): a front end says how it spells them; the CLI adds
    its flags to the line it prints and exits with code 2 (a traceback only with --debug). `details`: facts
    about the problem a report keeps besides the message (JSON values), e.g. a refused transcript's match.
    """

    def __init__(self, message: str, param: str | tuple[str, ...] | None = None,
                 details: dict | None = None) -> None:
        super().__init__(message)
        self.param = param
        self.details = details

    @property
    def params(self) -> tuple[str, ...]:
        """The parameters the problem is about, as a tuple (empty when it names none)."""
        if self.param is None:
            return ()
        return (self.param,) if isinstance(self.param, str) else tuple(self.param)

    def __reduce__(self):  # a worker process's error crosses to the parent with its parameter
        return type(self), (str(self), self.param, self.details)
