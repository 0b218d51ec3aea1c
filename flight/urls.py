"""Checking MAVSDK connection URLs before MAVSDK sees them.

MAVSDK answers a bad URL with a bare `CONNECTION_URL_INVALID` or `SOCKET_ERROR`
(and a log line on stderr); this module says what is wrong and how to fix it,
naming the URL. Forms accepted (the MAVSDK 2+ spellings):

    udpin://0.0.0.0:14540        listen on a UDP port (PX4 SITL sends to 14540)
    udpout://192.168.1.10:14550  send to a vehicle's UDP port
    tcpin://0.0.0.0:5760 / tcpout://192.168.1.10:5760
    serial:///dev/ttyACM0:57600  (or serial://COM3:57600)
"""

from __future__ import annotations

import ipaddress
import logging
import re

from flight.errors import ConnectionUrlError

log = logging.getLogger(__name__)

_NETWORK_SCHEMES = ("udpin", "udpout", "tcpin", "tcpout")
_DEPRECATED = {"udp": "udpin", "tcp": "tcpout"}
_BAUD_RATES = {9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 921600, 1500000, 2000000, 3000000}
_EXAMPLES = "e.g. udpin://0.0.0.0:14540, udpout://192.168.1.10:14550 or serial:///dev/ttyACM0:57600"


def validate_connection_url(url: str) -> str:
    """Return `url` unchanged if MAVSDK can open it, else raise `ConnectionUrlError` explaining the fix."""
    match = re.fullmatch(r"([a-z]+)://(.*)", url.strip())
    if match is None:
        raise ConnectionUrlError(url, f"not a connection URL; use scheme://address, {_EXAMPLES}")
    scheme, rest = match.groups()
    if scheme == "serial":
        return _check_serial(url, rest)
    if scheme in _DEPRECATED:
        log.warning("%r uses the deprecated scheme %s://; prefer %s://", url, scheme, _DEPRECATED[scheme])
    elif scheme not in _NETWORK_SCHEMES:
        raise ConnectionUrlError(
            url, f"unknown scheme {scheme!r}; use one of udpin, udpout, tcpin, tcpout, serial"
        )
    host, _, port_text = rest.rpartition(":")
    if not port_text.isdigit() or not 1 <= int(port_text) <= 65535:
        raise ConnectionUrlError(url, f"the port must be a number from 1 to 65535, {_EXAMPLES}")
    if host == "" and scheme in _DEPRECATED:
        return url
    if host == "":
        raise ConnectionUrlError(
            url,
            f"no address before the port: MAVSDK needs one; listen on all interfaces with "
            f"{scheme}://0.0.0.0:{port_text} or on loopback only with {scheme}://127.0.0.1:{port_text}",
        )
    try:
        ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        fix = "127.0.0.1" if host == "localhost" else "the vehicle's numeric IP address"
        raise ConnectionUrlError(
            url, f"MAVSDK accepts only numeric addresses, not {host!r}: use {scheme}://{fix}:{port_text}"
        ) from None
    return url


def _check_serial(url: str, rest: str) -> str:
    device, _, baud_text = rest.rpartition(":")
    if not device:
        raise ConnectionUrlError(
            url,
            "a serial URL needs a device and a baud rate: serial://DEVICE:BAUD, e.g. serial:///dev/ttyACM0:57600",
        )
    if not baud_text.isdigit() or int(baud_text) not in _BAUD_RATES:
        raise ConnectionUrlError(
            url,
            f"baud rate {baud_text!r} is not one of {sorted(_BAUD_RATES)} (radios: usually 57600)",
        )
    return url


def udpin_address(url: str) -> tuple[str, int] | None:
    """(host, port) of a valid `udpin://HOST:PORT` URL (where a relay in front of it listens), else None."""
    validate_connection_url(url)
    match = re.fullmatch(r"udpin://([0-9.]+):(\d+)", url.strip())
    return None if match is None else (match.group(1), int(match.group(2)))
