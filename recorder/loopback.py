"""Whether an address stays on this machine: the one test for where a token may be sent, and
where a view with no token of its own may be served (the recorder's control, the live view,
``play``, the API's warning)."""

from __future__ import annotations

import ipaddress

__all__ = ["is_loopback"]


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 or localhost."""
    name = host.strip("[]").lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False
