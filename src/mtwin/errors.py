"""Typed exceptions and exit codes shared by the library and the CLI.

Exit codes follow the ruff/HTTPie convention: 0 success, 1 a check failed
(``mtwin verify`` found a difference), 2 bad input or usage.
"""
from __future__ import annotations

from dataclasses import dataclass

EXIT_OK = 0
EXIT_CHECK_FAILED = 1
EXIT_BAD_INPUT = 2


@dataclass
class SourceLocation:
    """A place in a program: file name, 1-based line and column."""

    path: str
    line: int
    col: int

    def __str__(self) -> str:
        # (a place in no line — a log's whole run, a file's metadata — is the file alone, not
        # "file:0:0", the form warning_text writes too)
        if self.line <= 0:
            return self.path
        return f"{self.path}:{self.line}:{self.col}"


def warning_text(path: str, line: int, message: str, col: int = 1) -> str:
    """A warning in the one form every mtwin warning takes: ``file:line:col: warning: …``, or
    ``file: warning: …`` when it belongs to no line."""
    if line > 0:
        return f"{path}:{line}:{col}: warning: {message}"
    return f"{path}: warning: {message}"


class MtwinError(Exception):
    """Base class of every error mtwin reports to a user (exit code 2)."""

    exit_code = EXIT_BAD_INPUT


class GCodeError(MtwinError):
    """A program that cannot be read or interpreted, with its location."""

    def __init__(self, message: str, location: SourceLocation | None = None):
        super().__init__(message)
        self.message = message
        self.location = location

    def __str__(self) -> str:
        if self.location is None:
            return self.message
        return f"{self.location}: {self.message}"


class ConfigError(MtwinError):
    """A configuration file or parameter that is invalid; names the key."""


class WriteError(MtwinError):
    """A requested rewrite that cannot be expressed in G-code."""
