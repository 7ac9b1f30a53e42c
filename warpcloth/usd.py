"""Moved to :mod:`warpcloth.io.usd`; this forwarding module stays for one release."""

from warpcloth.io.usd import *  # noqa: F401,F403
