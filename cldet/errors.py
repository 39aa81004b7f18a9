"""The one exception family of cldet: library code raises these, the CLI turns them into messages."""

from __future__ import annotations


class CldetError(Exception):
    """Base of every error cldet raises on purpose; the message names the file or value at fault."""


class DatasetError(CldetError):
    """The challenge dataset (folders of .npy/.png files) is missing, malformed or inconsistent."""


class LogError(CldetError):
    """An MCAP log cannot be read or written as expected (missing topic, corrupt file, ...)."""


class ConfigError(CldetError):
    """A configuration file or option is invalid (unknown key, wrong type, bad value)."""


class ResultsError(CldetError):
    """A results, timestamps or truth CSV is malformed or does not match what it is scored against."""


class OutputExistsError(CldetError):
    """An output already exists and overwriting was not requested."""
