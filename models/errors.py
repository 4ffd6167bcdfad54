"""pantohil's errors and exit codes: one table of codes, one hierarchy of errors that carry theirs.

Every error pantohil raises on purpose derives from `PantohilError` and carries the exit code the
command line ends with; the builtin bases (ValueError, RuntimeError) are kept so that library callers
that catch those still do. An input error names the key (or file) that is wrong; the command line adds
its option where there is one and maps every error to its code in one place (orchestrator/cli.py).
"""
from __future__ import annotations

from enum import IntEnum


class ExitCode(IntEnum):
    """The exit codes of the `pantohil` command (docs/user-guide.md "Exit codes" is generated from
    EXIT_CODE_MEANINGS, and a test keeps it so)."""

    SUCCESS = 0
    FAILED = 1
    BAD_INPUT = 2
    LINK_LOST = 3


EXIT_CODE_MEANINGS: dict[str, str] = {
    "0": "success: a run converged, or completed the fixed length it was asked for (`run.duration_s`: status "
         "`completed`, `converged` false, when its last span did not meet `run.convergence_tol`)",
    "1": "a run diverged, lost contact (`contact_lost`) or reached `run.max_spans` without converging; an FMU "
         "failed; a disk full or a file size limit reached (one line; what was written stays readable); `watch` "
         "of a run that was killed",
    "2": "bad input: case, catenary, rig or operator file, SSP, command line; or a tool the command needs is "
         "missing (no C compiler to build the FMUs' loader); one line on stderr names what is wrong and nothing "
         "is written",
    "3": "the link to the rig was lost: the last position is held, the MCAP log is complete up to that instant",
    "130 / 143 / 129": "stopped by SIGINT (Ctrl-C) / SIGTERM / SIGHUP: a run's folder is complete, "
                       "`summary.json` says `interrupted`; a sweep writes the points done first; any other "
                       "command leaves no output (one line on stderr)",
}
"""What each exit code means, in the order docs/user-guide.md lists them."""


def exit_code_table() -> str:
    """The "Exit codes" table of docs/user-guide.md, as Markdown."""
    rows = ["| code | meaning |", "| --- | --- |"]
    rows += [f"| {code} | {meaning} |" for code, meaning in EXIT_CODE_MEANINGS.items()]
    return "\n".join(rows) + "\n"


class PantohilError(Exception):
    """The base of every error pantohil raises on purpose; `exit_code` is the command's exit code."""

    exit_code: ExitCode = ExitCode.FAILED

    def line(self) -> str:
        """The error as the one line the command line prints."""
        return " ".join(str(self).split())


class InputError(PantohilError, ValueError):
    """Bad input (a file, a key, a value, a datagram's content): one line naming what is wrong, exit 2.
    `key` is the case key or file the error is about, when there is one."""

    exit_code = ExitCode.BAD_INPUT

    def __init__(self, message: str = "", key: str | None = None):
        super().__init__(message)
        self.key = key


class UsageError(InputError):
    """A command line that cannot run; `option` names the option."""

    def __init__(self, message: str = "", option: str | None = None):
        super().__init__(message, key=option)
        self.option = option


class SetupError(PantohilError, RuntimeError):
    """A tool the command needs is missing or fails (the C compiler of the FMUs' loader): exit 2, before
    anything is written."""

    exit_code = ExitCode.BAD_INPUT


class FmuFailure(PantohilError, RuntimeError):
    """An FMU returned an error status or failed to load: exit 1."""

    exit_code = ExitCode.FAILED


class LinkError(PantohilError, RuntimeError):
    """The link to the rig was lost or refused: exit 3."""

    exit_code = ExitCode.LINK_LOST
