"""When progress bars are drawn: only where someone watches them."""

from __future__ import annotations


def bar_disabled(progress: bool) -> bool | None:
    """tqdm's ``disable`` for a caller that asked for ``progress``: None lets tqdm draw the
    bar on a terminal only, so a service's log or a redirected run never fills with bar
    redraws; False progress hides it everywhere."""
    return None if progress else True
