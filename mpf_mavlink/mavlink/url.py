"""MAVLink connection strings (pymavlink's syntax, see :mod:`.link`): validated into a
:class:`ParsedUrl` with one-line errors naming the culprit."""

from __future__ import annotations

import ipaddress
import os
import re
import socket
from dataclasses import dataclass

from mpf_mavlink.errors import MpfError

SCHEMES = ("udpin", "udpout", "udp", "tcp", "tcpin")
STANDARD_BAUDS = (
    9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600,
    1000000, 1500000, 2000000, 3000000,
)  # fmt: skip
MAV_COMP_ID_ONBOARD_COMPUTER = 191
_HOSTNAME_RE = re.compile(
    r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*$"
)


@dataclass(frozen=True)
class ParsedUrl:
    kind: str  # "udpin" | "udpout" | "tcp" | "tcpin" | "serial"
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0

    @property
    def pymavlink_device(self) -> str:
        if self.kind == "serial":
            return self.device
        return f"{self.kind}:{self.host}:{self.port}"


def _parse_host_port(url: str, scheme: str, rest: str) -> tuple[str, int]:
    form = f"expected {scheme}:HOST:PORT, e.g. {scheme}:127.0.0.1:14550"
    parts = rest.rsplit(":", 1)
    if len(parts) != 2 or not parts[0]:
        raise MpfError(f"bad MAVLink URL {url!r}: {form}")
    host, port_s = parts
    if not re.fullmatch(r"\d{1,5}", port_s):
        raise MpfError(f"bad MAVLink URL {url!r}: port {port_s!r} is not a number ({form})")
    port = int(port_s)
    if not 1 <= port <= 65535:
        raise MpfError(f"bad MAVLink URL {url!r}: port {port} is outside 1..65535")
    try:
        ipaddress.IPv4Address(host)
    except ValueError:
        if re.fullmatch(r"[\d.]+", host) or not _HOSTNAME_RE.match(host):
            raise MpfError(
                f"bad MAVLink URL {url!r}: {host!r} is not an IPv4 address or host name"
            ) from None
    return host, port


def parse_url(url: str, baud: int | None = None) -> ParsedUrl:
    """Validate a connection string; raise MpfError with one line naming the culprit."""
    if not isinstance(url, str) or not url.strip():
        raise MpfError("empty MAVLink URL: use e.g. udpin:0.0.0.0:14540 or /dev/ttyUSB0:57600")
    url = url.strip()
    if url.startswith("/") or re.match(r"^COM\d+", url, re.I):
        device, b = url, baud
        if not os.path.exists(url):
            m = re.fullmatch(r"(.+)[:,]([^:,/]*)", url)
            if m:
                device, tail = m.group(1), m.group(2)
                if not tail.isdigit():
                    raise MpfError(f"bad MAVLink URL {url!r}: baud rate {tail!r} is not a number")
                b = int(tail)
        b = 57600 if b is None else int(b)
        if b not in STANDARD_BAUDS:
            raise MpfError(
                f"bad MAVLink URL {url!r}: unsupported baud rate {b} (use one of {STANDARD_BAUDS})"
            )
        return ParsedUrl("serial", device=device, baud=b)
    if ":" not in url:
        raise MpfError(
            f"bad MAVLink URL {url!r}: expected SCHEME:HOST:PORT with SCHEME one of "
            f"{', '.join(SCHEMES)}, or a serial device path"
        )
    scheme, rest = url.split(":", 1)
    if scheme.lower() not in SCHEMES:
        raise MpfError(
            f"bad MAVLink URL {url!r}: unknown scheme {scheme!r} (use one of {', '.join(SCHEMES)}, "
            "or a serial device path)"
        )
    scheme = scheme.lower()
    host, port = _parse_host_port(url, scheme, rest)
    kind = "udpin" if scheme == "udp" else scheme
    return ParsedUrl(kind, host=host, port=port)


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 free a moment ago (for a local ``udpin:`` end to listen on)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = int(s.getsockname()[1])
    s.close()
    return port
