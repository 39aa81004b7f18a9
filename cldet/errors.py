"""The one exception family of cldet: library code raises these, the CLI turns them into messages."""

from __future__ import annotations


class CldetError(Exception):
    """Base of every error cldet raises on purpose; the message names the file or value at fault."""


class DatasetError(CldetError):
    """The challenge dataset (folders of .npy/.png files) is missing, malformed or inconsistent."""


class LogError(CldetError):
    """An MCAP log cannot be read or written as expected (missing topic, corrupt file, ...)."""


class CorruptMessageError(LogError):
    """One message of a log cannot be decoded; names the log, the topic and the stamp."""

    def __init__(self, message: str, *, log: object, topic: str, stamp_ns: int) -> None:
        super().__init__(message)
        self.log = log
        self.topic = topic
        self.stamp_ns = stamp_ns  # the message's log time, integer ns

    def __reduce__(self) -> tuple[object, ...]:  # pickled across worker processes
        return (_corrupt_message, (str(self), self.log, self.topic, self.stamp_ns))


def _corrupt_message(message: str, log: object, topic: str, stamp_ns: int) -> CorruptMessageError:
    return CorruptMessageError(message, log=log, topic=topic, stamp_ns=stamp_ns)


class FrameOrderError(CldetError):
    """Frames reached the estimator out of stamp order, or two frames share one stamp."""


class ConfigError(CldetError):
    """A configuration file or option is invalid (unknown key, wrong type, bad value)."""


class ResultsError(CldetError):
    """A results, timestamps or truth CSV is malformed or does not match what it is scored against."""


class OutputError(CldetError):
    """An output cannot be written where it was asked (missing folder, a directory, no access)."""


class OutputExistsError(CldetError):
    """An output already exists and overwriting was not requested."""


class ExecutorError(CldetError):
    """Jobs could not be run in parallel: an unknown executor, Ray missing or unreachable, a
    worker process that died."""
