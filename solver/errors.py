"""Exceptions raised for bad user input.  Their message names the file, frame, key or object and
what is wrong; operators report it and batch commands print it and exit non-zero."""


class ArticulaInputError(ValueError):
    """The input (file, array, parameter) cannot be used; the message says why."""


class Cancelled(Exception):
    """Long work was cancelled by the user (Esc) or the caller's progress callback."""
