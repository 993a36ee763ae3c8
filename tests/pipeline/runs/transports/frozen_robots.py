"""Shared by the frozen-robot tests of this folder: a transport's online job whose robot is
frozen (``kill -STOP``, then ``kill -CONT`` ``stop_s`` seconds later) on chosen calls."""


def freezing(job, calls, frozen: int, stop_s: float, status: str = "consistency"):
    """``job`` with its robot ``frozen`` stopped for ``stop_s`` s as soon as it publishes
    ``status`` (``consistency``: the start of its consistency stage), on its calls numbered
    in ``calls`` (from 0)."""
    seen = []

    def wrapped(*args, **kw):
        seen.append(1)
        if len(seen) - 1 in calls:
            kw["kill"] = (frozen, status, 0.0, stop_s)
        return job(*args, **kw)

    return wrapped
