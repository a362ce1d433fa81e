"""Errors a user can cause and fix: the command line prints them as one line and exits 2."""


class DtdError(Exception):
    """A problem with the user's input or files, reported without a traceback."""


class ConfigError(DtdError):
    """A setting that cannot work."""


class EnvError(DtdError):
    """An environment that cannot be made or is not goal-conditioned."""


class RunDirError(DtdError):
    """A run directory that is missing, already used, or holds unreadable files."""


class CheckpointError(DtdError):
    """A checkpoint that is missing, corrupt, or belongs to another run."""


class MachineError(Exception):
    """A failure of the machine rather than of the input (a full disk, an I/O error), reported
    as one line with the operating system's reason; the command line exits 1."""


class WorkerLost(MachineError):
    """A data-parallel worker lost contact with the others of its run (one of them died, or
    was cut off): the job stops, and the run resumes from its last finished epoch."""
