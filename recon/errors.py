"""The one exception type that the CLI turns into a one-line message and exit code 2."""


class UserError(Exception):
    """Bad input or a state the user can fix: an empty folder, a corrupt image, no model yet.

    The message is one line, names the file or cause, and says what to do where possible.
    """
