"""Errors a user can cause; the CLI and the stages print them as one line, no traceback."""


class PipelineError(Exception):
    """Base of every user-facing error; ``str(err)`` is the one line to show."""


class BadInputError(PipelineError):
    """An input file or array that cannot be used (empty, NaN, open, wrong units...)."""


class BadParamsError(PipelineError):
    """A params.yaml section or CLI option with a missing, unknown or invalid value."""


class DegenerateGeometryError(PipelineError):
    """Geometry from which no result can be computed (e.g. every medial ball collapsed)."""


class ArtefactError(PipelineError):
    """An artefact file that is missing, corrupt or of another schema version."""


class WorkerError(PipelineError):
    """A worker process that ended abruptly (killed by a signal, or by the system for memory)."""
