"""Moved to :mod:`warpcloth.sim.model`; this forwarding module stays for one release."""
from warpcloth.sim.model import *  # noqa: F401,F403
