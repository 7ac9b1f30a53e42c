"""User-facing errors.

Every check on user input raises :class:`WarpclothError` (a ``ValueError``) with a one-line
message that names the bad value and what is allowed. The CLI prints it and exits with status 2.
A result that is produced but is not what was asked (e.g. a solver that missed its tolerance)
prints one line, ``warpcloth: warning: ...``, on stderr (:func:`warn`).
"""

import math
import numbers
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


def require_number(name: str, value, unit: str = "") -> float:
    """Return ``value`` as a float if it is a finite number in float32's range, else raise."""
    return _as_float(name, value)


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


def require_count(name: str, value, minimum: int = 0) -> int:
    """An integer count (``int`` or an integral NumPy integer, not a float, string or bool)
    >= ``minimum``, else raise: for step counts and iteration counts."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise WarpclothError(f"{name} must be an integer >= {minimum}, got {value!r}")
    require(int(value) >= minimum, f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def require_indices(name: str, value, count: int):
    """A 1-D int64 array of particle indices in 0..count-1 from a sequence of integers (Python or
    NumPy ints, or integral floats); else raise naming the first bad entry."""
    import numpy as np  # noqa: PLC0415 (keeps `warpcloth --version` free of NumPy)

    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise WarpclothError(
            f"{name} must be a sequence of particle indices (integers 0..{count - 1}), got {value!r:.80}"
        )
    out = []
    for v in value:
        ok = not isinstance(v, bool) and (
            isinstance(v, numbers.Integral) or (isinstance(v, numbers.Real) and float(v).is_integer())
        )
        if not ok:
            raise WarpclothError(f"{name} must hold integer particle indices 0..{count - 1}, got {v!r}")
        iv = int(v)
        if not 0 <= iv < count:
            what = name[:-1] if name.endswith("s") else name
            raise WarpclothError(f"{what} index {iv} is out of range: particles are 0..{count - 1}")
        out.append(iv)
    return np.unique(np.asarray(out, dtype=np.int64))


def require_vector(name: str, value, size: int = 3, unit: str = "") -> tuple:
    """A tuple of ``size`` finite float32-range numbers, else raise."""
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != size:
        raise WarpclothError(f"{name} must be {size} numbers{(' [' + unit + ']') if unit else ''}, got {value!r:.80}")
    return tuple(_as_float(f"{name}[{k}]", v) for k, v in enumerate(value))


def _as_float(name: str, value) -> float:
    if isinstance(value, (str, bytes, bool)):
        raise WarpclothError(f"{name} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise WarpclothError(f"{name} must be a number, got {value!r:.80}") from None
    require(math.isfinite(v), f"{name} must be a finite number, got {value!r}")
    require(abs(v) <= FLOAT32_MAX, f"{name} must fit in float32 (|value| <= {FLOAT32_MAX:.4g}), got {value!r}")
    return v


FLOAT32_MAX = 3.4028234663852886e38
