"""The error every dataset reader raises for a malformed file or episode."""


class DatasetError(ValueError):
    """A dataset file or episode is malformed; the message names the file or episode."""
