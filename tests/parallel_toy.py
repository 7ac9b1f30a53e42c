"""A job function for tests/test_parallel.py's worker pools: importable without Warp, so that a
spawned worker starts in a fraction of a second."""

import os
import signal
import time


def toy(payload, place):
    """("ok", x) -> a row; ("raise", x) raises; ("die", _) SIGKILLs its worker; ("die_once", path)
    SIGKILLs it the first time (marked by creating path); ("sleep", s) sleeps first; ("barrier",
    (folder, mine, other)) returns once the job ``other`` has started too."""
    kind, arg = payload
    if kind == "raise":
        raise ValueError(f"bad payload {arg}")
    if kind == "die" or (kind == "die_once" and not os.path.exists(arg)):
        if kind == "die_once":
            open(arg, "w").close()
        os.kill(os.getpid(), signal.SIGKILL)
    if kind == "sleep":
        time.sleep(arg)
    if kind == "barrier":  # (folder, mine, other): both jobs must be running at once to return
        folder, mine, other = arg
        open(os.path.join(folder, mine), "w").close()
        deadline = time.monotonic() + 120
        while not os.path.exists(os.path.join(folder, other)):
            if time.monotonic() > deadline:
                raise TimeoutError(f"{other} never started")
            time.sleep(0.01)
    return {"value": arg, "pid": os.getpid(), "worker": place.worker}
