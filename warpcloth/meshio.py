"""Moved to :mod:`warpcloth.io.meshio`; this forwarding module stays for one release."""

from warpcloth.io.meshio import *  # noqa: F401,F403
