"""One address grammar for every command: where a peer is, and whether we listen or connect.

Transfers between processes travel over a byte stream (decision S): ``--listen tcp://HOST:PORT``
(port 0: any free port, printed), ``--port URL`` (``tcp://``, ``socket://``, ``rfc2217://``, a tty
or pty path) and, on SPI lines, ``MASTER_URL,SLAVE_URL`` or a ``bench.toml``
(:mod:`eyeq_spi.phy.bench`). :func:`parse_connect` and :func:`parse_listen` are the only parsers."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import Literal

from eyeq_spi.errors import AdapterError

CONNECT_FORMS = "tcp://HOST:PORT, socket://HOST:PORT, rfc2217://HOST:PORT or a tty/pty path"
LISTEN_FORM = "tcp://HOST:PORT (port 0: any free port)"

_URL = re.compile(r"^([a-z0-9+]+)://(\[[0-9A-Fa-f:.]+\]|[^:/\[\]\s?#]*):([^/?#]*)(.*)$")


@dataclass(frozen=True)
class Address:
    """A parsed address: ``mode`` says whether we listen or connect; ``url`` is canonical
    (listen: ``tcp://HOST:PORT``; connect: the pyserial URL or device path we open)."""

    mode: Literal["listen", "connect"]
    url: str
    host: str | None = None
    port: int | None = None

    @property
    def display(self) -> str:
        """The address in the new grammar (what a user types)."""
        if self.host is not None and self.url.startswith("socket://"):
            return "tcp://" + self.url[len("socket://"):]
        return self.url


def _host_port(text: str, lo_port: int) -> tuple[str, str, int, str]:
    match = _URL.match(text.strip())
    if not match:
        raise AdapterError(f"{text!r} is not SCHEME://HOST:PORT")
    scheme, host, port_text, rest = match.groups()
    if rest and not rest.startswith("?"):
        raise AdapterError(f"{text!r}: nothing may follow :PORT")
    try:
        port = int(port_text)
    except ValueError:
        raise AdapterError(f"{text!r}: the port must be an integer in {lo_port}..65535, "
                           f"got {port_text!r}") from None
    if not lo_port <= port <= 65535:
        raise AdapterError(f"{text!r}: the port must be in {lo_port}..65535")
    return scheme, host or "127.0.0.1", port, rest


def _bare(host: str) -> str:
    return host[1:-1] if host.startswith("[") else host


def parse_listen(text: str) -> Address:
    """``tcp://HOST:PORT`` to listen on."""
    if "://" not in text:
        raise AdapterError(f"{text!r}: give {LISTEN_FORM}")
    scheme = text.split("://", 1)[0].lower()
    if scheme != "tcp":
        raise AdapterError(f"cannot listen on {scheme}://; give {LISTEN_FORM}")
    _, host, port, rest = _host_port(text, 0)
    if rest:
        raise AdapterError(f"{text!r}: a listening address takes no options after :PORT")
    url = f"tcp://{host}:{port}"
    return Address("listen", url, _bare(host), port)


def parse_connect(text: str, *, check_path: bool = True) -> Address:
    """Where to connect: ``tcp://`` or ``socket://HOST:PORT``, ``rfc2217://HOST:PORT``, or a
    tty/pty path (``check_path``: it must exist). Any other pyserial URL (``loop://``...) is
    passed through for :func:`open_url`'s callers in code."""
    if "://" not in text:
        if check_path and not os.path.exists(text):
            raise AdapterError(f"no such device {text!r}; give {CONNECT_FORMS}")
        return Address("connect", text)
    scheme = text.split("://", 1)[0].lower()
    if scheme in ("tcp", "socket", "rfc2217"):
        _, host, port, rest = _host_port(text, 1)
        url = f"{'rfc2217' if scheme == 'rfc2217' else 'socket'}://{host}:{port}{rest}"
        return Address("connect", url, _bare(host), port)
    return Address("connect", text)


SPI_SCHEMES = ("spidev", "ft4222")
SPI_FORMS = ("MASTER_URL,SLAVE_URL (spidev:///dev/spidevB.C, ft4222://SERIAL_OR_INDEX) "
             "or a bench.toml")


def is_spi(text: str) -> bool:
    """Whether ``text`` names one side on SPI lines: a pair of ``spidev://`` or ``ft4222://``
    channels, or a bench file (:mod:`eyeq_spi.phy.bench`)."""
    first = text.split(",", 1)[0]
    return first.split("://", 1)[0].lower() in SPI_SCHEMES or text.endswith(".toml")


def listen_url(host: str, port: int) -> str:
    """The URL a peer gives to ``--port`` to reach a listener on ``host:port`` (a wildcard
    address becomes loopback, so the URL works as printed on this machine)."""
    host = {"0.0.0.0": "127.0.0.1", "": "127.0.0.1", "::": "::1"}.get(host, host)
    return f"tcp://{f'[{host}]' if ':' in host else host}:{port}"
