"""Ctrl-C or SIGTERM in disguise: a KeyboardInterrupt that lands while a module is
imported or a class is made reaches the command line wrapped in another error
(``ImportError: initialization failed`` from an extension module's start,
``RuntimeError: Error calling __set_name__`` from a dataclass being made)."""

from __future__ import annotations


def caused_by_interrupt(error: BaseException) -> bool:
    """Whether a KeyboardInterrupt is among the causes of ``error``."""
    seen: set[int] = set()
    cause: BaseException | None = error
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False
