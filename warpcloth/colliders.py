"""Moved to :mod:`warpcloth.sim.colliders`; this forwarding module stays for one release."""
from warpcloth.sim.colliders import *  # noqa: F401,F403
