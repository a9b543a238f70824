"""The one exception type for errors a user can cause."""


class FacegenError(Exception):
    """A problem with the user's input or environment.

    The message says what is wrong and how to fix it, in one line; the CLI prints it
    and exits with code 2 (a traceback only with --debug).
    """
