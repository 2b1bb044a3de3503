"""The one exception type for user-facing failures."""


class GtsamDvlError(Exception):
    """A failure the user can act on (bad input file, bad configuration, unsolvable problem).

    The command line turns it into one line on stderr and exit code 1; a traceback only with --debug.
    """
