"""User-facing errors.

Every check on user input raises :class:`WarpclothError` (a ``ValueError``) with a one-line
message that names the bad value and what is allowed. The CLI prints it and exits with status 2.
A result that is produced but is not what was asked (e.g. a solver that missed its tolerance)
prints one line, ``warpcloth: warning: ...``, on stderr (:func:`warn`).
"""

import sys


class WarpclothError(ValueError):
    """Bad user input: the message names the value and what is allowed."""


def warn(message: str) -> None:
    """Print ``warpcloth: warning: <message>`` as one line on stderr."""
    print(f"warpcloth: warning: {message}", file=sys.stderr, flush=True)


def require(condition: bool, message: str) -> None:
    """Raise :class:`WarpclothError` with ``message`` unless ``condition`` holds."""
    if not condition:
        raise WarpclothError(message)


def require_positive(name: str, value, unit: str = "") -> float:
    """Return ``value`` as a float if it is a finite number > 0, else raise."""
    v = _as_float(name, value)
    require(v > 0.0, f"{name} must be > 0{(' ' + unit) if unit else ''}, got {value!r}")
    return v


def require_non_negative(name: str, value, unit: str = "") -> float:
    """Return ``value`` as a float if it is a finite number >= 0, else raise."""
    v = _as_float(name, value)
    require(v >= 0.0, f"{name} must be >= 0{(' ' + unit) if unit else ''}, got {value!r}")
    return v


def require_int(name: str, value, minimum: int) -> int:
    """Return ``value`` as an int if it is an integer >= ``minimum``, else raise."""
    try:
        iv = int(value)
    except (TypeError, ValueError, OverflowError):  # OverflowError: inf
        raise WarpclothError(f"{name} must be an integer >= {minimum}, got {value!r}") from None
    require(iv == value if isinstance(value, float) else True, f"{name} must be an integer >= {minimum}, got {value!r}")
    require(iv >= minimum, f"{name} must be an integer >= {minimum}, got {value!r}")
    return iv


def _as_float(name: str, value) -> float:
    import math

    try:
        v = float(value)
    except (TypeError, ValueError):
        raise WarpclothError(f"{name} must be a number, got {value!r}") from None
    require(math.isfinite(v), f"{name} must be a finite number, got {value!r}")
    require(abs(v) <= FLOAT32_MAX, f"{name} must fit in float32 (|value| <= {FLOAT32_MAX:.4g}), got {value!r}")
    return v


FLOAT32_MAX = 3.4028234663852886e38
