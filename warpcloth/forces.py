"""Moved to :mod:`warpcloth.sim.control` and :mod:`warpcloth.integrators.forces`; forwarding for one release."""

from warpcloth.integrators.forces import *  # noqa: F401,F403
from warpcloth.sim.control import *  # noqa: F401,F403
