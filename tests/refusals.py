"""How the tests check a refusal: by the argument it names and its one-line form.

The package refuses a bad input with one line, "argument: what is wrong" (a ValueError naming
the argument, or the input's place: "m.csv line 3: ...", "formulation 'SiC-50': ..."); the
console prints it as "itr: error: argument: what is wrong" with no traceback. The wording
after the name is free to change, so most tests check only the name and the form:

    with refuses(ValueError, "tol"):
        solve(..., tol=0.0)

    with pytest.raises(ValueError) as info:
        ...
    refused(info, "voxel_um")

A test whose subject is the sentence itself (a suggested fix, a unit conversion hint, the
listed choices) matches that part of it as well.
"""

from __future__ import annotations

import contextlib

import pytest

__all__ = ["refused", "refused_on_cli", "refuses"]


def refused(exc_info, argument: str) -> str:
    """Assert that a refusal (a pytest ExceptionInfo, an exception or its message) reads
    "<argument>: <what is wrong>" in one line; return the message."""
    value = getattr(exc_info, "value", exc_info)
    msg = value if isinstance(value, str) else str(value)
    head = f"{argument}: "
    assert msg.startswith(head), f"the refusal should name {argument!r} first: {msg!r}"
    assert msg[len(head):].strip(), f"the refusal names {argument!r} but says nothing: {msg!r}"
    assert "\n" not in msg, f"the refusal should be one line: {msg!r}"
    return msg


@contextlib.contextmanager
def refuses(exception, argument: str):
    """pytest.raises(exception), then refused(): the error names `argument` in one line.
    Yields the ExceptionInfo."""
    with pytest.raises(exception) as info:
        yield info
    refused(info, argument)


def refused_on_cli(stderr: str, argument: str, prog: str = "itr") -> str:
    """Assert that a console command's stderr is the one line "<prog>: error: <argument>:
    <what is wrong>" and no traceback; return the message after "<prog>: error: "."""
    assert "Traceback" not in stderr, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and stderr.endswith("\n"), f"expected one line: {stderr!r}"
    prefix = f"{prog}: error: "
    assert lines[0].startswith(prefix), f"expected {prefix!r} first: {stderr!r}"
    return refused(lines[0][len(prefix):], argument)
