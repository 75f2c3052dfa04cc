"""Who a UI request comes from, as the login throttle and the audit name it: every loopback
address is one client (each local user has all of 127.0.0.0/8), an IPv6 /64 is one, and behind
a proxy the UI was told to trust (`--trusted-proxy`) the client is the X-Forwarded-For's last
hop that is not a trusted proxy. Pure: the request's peer and header in, a key out."""

from __future__ import annotations

import ipaddress
from collections.abc import Iterable, Sequence

from robotconf.readmodel.http_edge import client_key

LOOPBACK = "loopback"
MAX_PROXIES = 16
MAX_FORWARDED = 4096  # characters of X-Forwarded-For looked at; beyond, the proxy is the client
MAX_HOPS = 32

Network = ipaddress.IPv4Network | ipaddress.IPv6Network
Address = ipaddress.IPv4Address | ipaddress.IPv6Address


def parse_proxies(given: Iterable[str], option: str = "--trusted-proxy") -> tuple[Network, ...]:
    """The `--trusted-proxy` addresses or networks (10.0.0.5, 10.0.0.0/24, ::1); ValueError
    saying which one is not."""
    proxies: list[Network] = []
    for text in given:
        try:
            proxies.append(ipaddress.ip_network(text.strip(), strict=False))
        except ValueError:
            raise ValueError(
                f"{option} {text[:80]!r} is not an IP address or network (e.g. 10.0.0.5 or "
                "10.0.0.0/24): the address the proxy connects to this UI from"
            ) from None
    if len(proxies) > MAX_PROXIES:
        raise ValueError(f"{option} is given more than {MAX_PROXIES} times")
    return tuple(proxies)


def _address(text: str) -> Address | None:
    try:
        address = ipaddress.ip_address(text.strip().split("%", 1)[0])
    except ValueError:
        return None
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return address.ipv4_mapped
    return address


def _trusted(address: Address | None, proxies: Sequence[Network]) -> bool:
    return address is not None and any(address in network for network in proxies)


def key_of(address: Address | None, raw: str) -> str:
    """The throttle's key for one address: all of loopback is one."""
    if address is not None and address.is_loopback:
        return LOOPBACK
    return client_key(str(address) if address is not None else raw)


def client_of(peer: str, forwarded: Sequence[str], proxies: Sequence[Network]) -> str:
    """The key of the client behind a request from `peer` carrying `forwarded` (its
    X-Forwarded-For headers, in order): the header counts only when `peer` is a trusted
    proxy, and then only its hops from the right up to the first that is not one; a header
    too long or a hop that is not an address leaves the proxy as the client."""
    address = _address(peer)
    if not _trusted(address, proxies) or not forwarded:
        return key_of(address, peer)
    text = ",".join(forwarded)
    hops = text.split(",")
    if len(text) > MAX_FORWARDED or len(hops) > MAX_HOPS:
        return key_of(address, peer)
    for hop in reversed(hops):
        found = _address(hop)
        if found is None:
            return key_of(address, peer)
        if not _trusted(found, proxies):
            return key_of(found, hop)
    return key_of(address, peer)  # every hop a proxy: the nearest is as far as we know
