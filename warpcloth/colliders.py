"""Moved to :mod:`warpcloth.sim.colliders` and :mod:`warpcloth.sim.contacts`; this forwarding module stays for
one release."""

from warpcloth.sim.colliders import *  # noqa: F401,F403
from warpcloth.sim.contacts import *  # noqa: F401,F403
