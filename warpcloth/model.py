"""Moved to :mod:`warpcloth.sim.model` and :mod:`warpcloth.sim.grid`; this forwarding module stays for one
release."""

# the old module's star export had these helpers too
from warpcloth.errors import require_int, require_positive, require_vector  # noqa: F401
from warpcloth.sim.device import require_memory  # noqa: F401
from warpcloth.sim.grid import *  # noqa: F401,F403
from warpcloth.sim.model import *  # noqa: F401,F403
