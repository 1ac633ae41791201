"""The exceptions of :mod:`stereonav`.

Every exception the package raises on purpose derives from :class:`Error`, and also from the
built-in exception a caller would expect (``ValueError``, ``TypeError``), so both
``except stereonav.Error`` and ``except ValueError`` work. The native module
:mod:`stereonav._native` raises :class:`InputError` from this module itself.
"""

from __future__ import annotations

__all__ = ["Error", "InputError", "InputTypeError"]


class Error(Exception):
    """Base class of every exception raised by :mod:`stereonav`."""


class InputError(Error, ValueError):
    """An argument has the right type but a value the stack cannot take.

    Examples: an image whose shape is not 2-D, or whose size, or a ``threshold`` or
    ``max_features``, is outside the camera board's register ranges (``board-icd.md``
    section 1). The message names the value that was wrong and the range allowed.
    """


class InputTypeError(Error, TypeError):
    """An argument has the wrong type: not a NumPy array, a dtype other than ``uint8``,
    or a number that is not an integer. The message names the type found.
    """
