"""Moved to :mod:`warpcloth.run.harness`; this forwarding module stays for one release."""

from warpcloth.run.harness import *  # noqa: F401,F403
