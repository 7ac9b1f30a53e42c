"""A job function for tests/test_parallel.py's worker pools: importable without Warp, so that a
spawned worker starts in a fraction of a second."""

import os
import signal
import time


def toy(payload, place):
    """("ok", x) -> a row; ("raise", x) raises; ("die", _) SIGKILLs its worker; ("die_once", path)
    SIGKILLs it the first time (marked by creating path); ("sleep", s) sleeps first."""
    kind, arg = payload
    if kind == "raise":
        raise ValueError(f"bad payload {arg}")
    if kind == "die" or (kind == "die_once" and not os.path.exists(arg)):
        if kind == "die_once":
            open(arg, "w").close()
        os.kill(os.getpid(), signal.SIGKILL)
    if kind == "sleep":
        time.sleep(arg)
    return {"value": arg, "pid": os.getpid(), "worker": place.worker}
