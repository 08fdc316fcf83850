"""The root of sit2stand's domain errors.

Every error that bad input, a bad file or a failed stage raises derives from :class:`Sit2StandError`, so a caller
catches one type; the ``sit2stand`` command turns it into one line on stderr and exit status 2. Each subclass also
derives from the built-in exception it refines (``ValueError``, ``RuntimeError``, ``KeyError``), so code that caught
those keeps working. Messages name the file, topic, field or value at fault and, where one exists, what would do.
"""

from __future__ import annotations


class Sit2StandError(Exception):
    """Base class of every sit2stand domain error."""


class InputError(Sit2StandError, ValueError):
    """A value, option or file content that cannot be used; the message names it and what would do."""
