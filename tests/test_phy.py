"""One adapter contract suite, run against every adapter (python-can's pattern)."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import pytest

from eyeq_spi.errors import AdapterError, LinkLostError
from eyeq_spi.phy.base import ADAPTERS, Adapter, adapter_class, open_url
from eyeq_spi.phy.memory import memory_pair
from eyeq_spi.phy.stream import CobsDecoder, encode_transfer
from eyeq_spi.phy.tcp import TcpListenAdapter

Ends = tuple[Adapter, Adapter]


def _memory() -> Iterator[Ends]:
    a, b = memory_pair()
    yield a, b
    a.close(), b.close()


def _loop() -> Iterator[Ends]:
    a = open_url("loop://")
    yield a, a  # loop:// is its own peer
    a.close()


def _tcp() -> Iterator[Ends]:
    server = TcpListenAdapter("127.0.0.1", 0, timeout=5.0)
    client = open_url(server.url)
    assert server.accept(5.0)
    yield client, server
    client.close(), server.close()


def _pty() -> Iterator[Ends]:
    from eyeq_spi.phy.pty import PtyAdapter

    ours = PtyAdapter()
    peer = open_url(ours.path)  # the peer opens the slave side as an ordinary serial port
    assert ours.accept(5.0)
    yield ours, peer
    ours.close(), peer.close()


# a pair of connected ends for every adapter of the registry (the serial adapter over pyserial's
# loop://); a new adapter without one fails test_every_registered_adapter_has_a_pair
def _spi() -> Iterator[Ends]:
    """Two SPI sides wired to each other over in-memory channels (each master to the other's
    slave); tests/test_phy_simwire.py runs the drivers' side over a simulated wire."""
    from eyeq_spi.phy.spi import SpiAdapter, SpiSettings
    from tests.test_phy_spi import Master, Slave

    a_master, a_slave, b_master, b_slave = Master(), Slave(), Master(), Slave()
    b_slave.lines, a_slave.lines = a_master.wire, b_master.wire
    a = SpiAdapter(a_master, a_slave, SpiSettings())  # type: ignore[arg-type]
    b = SpiAdapter(b_master, b_slave, SpiSettings())  # type: ignore[arg-type]
    yield a, b
    a.close(), b.close()


PAIRS = {"memory": _memory, "serial": _loop, "tcp-listen": _tcp, "pty": _pty, "spi": _spi}


def test_every_registered_adapter_has_a_pair() -> None:
    assert set(PAIRS) == set(ADAPTERS)


@pytest.fixture(params=sorted(ADAPTERS))
def ends(request: pytest.FixtureRequest) -> Iterator[Ends]:
    if request.param not in PAIRS:
        pytest.fail(f"adapter {request.param!r} has no pair in PAIRS")
    yield from PAIRS[request.param]()


def recv_wait(a: Adapter, timeout: float = 2.0) -> bytes | None:
    return a.recv(timeout)


TRANSFERS = [
    bytes(128),  # all zeros: the COBS worst case for delimiters
    bytes(range(128)),
    b"\xff" * 128,
    bytes(127),  # chip select rose early (L8): must arrive as it was
    bytes(129),
    b"\x00\x01",
]


def test_transfers_arrive_intact_and_in_order(ends: Ends) -> None:
    a, b = ends
    for t in TRANSFERS:
        a.send(t)
    got = [recv_wait(b) for _ in TRANSFERS]
    assert got == TRANSFERS
    assert a.stats.transfers_sent >= len(TRANSFERS)
    assert b.recv(0) is None


def test_poll_without_data_returns_none(ends: Ends) -> None:
    _, b = ends
    assert b.recv(0) is None


def test_closed_adapter_raises_adapter_error(ends: Ends) -> None:
    a, _ = ends
    a.close()
    with pytest.raises(AdapterError):
        a.send(bytes(128))
    with pytest.raises(AdapterError):
        a.recv(0)


def test_empty_transfer_is_refused(ends: Ends) -> None:
    a, _ = ends
    with pytest.raises(AdapterError):
        a.send(b"")


def test_registry_imports_on_demand_and_rejects_unknown_names() -> None:
    assert set(ADAPTERS) >= {"memory", "serial", "tcp-listen"}
    assert adapter_class("memory").__name__ == "MemoryAdapter"
    with pytest.raises(AdapterError):
        adapter_class("nope")


def test_bad_urls_are_adapter_errors() -> None:
    with pytest.raises(AdapterError):
        open_url("/dev/does-not-exist-eyeq")
    with pytest.raises(AdapterError):
        open_url("listen://127.0.0.1:notaport")
    with pytest.raises(AdapterError):
        open_url("bogus://x")


def test_cobs_framing_counts_garbage_and_recovers() -> None:
    dec = CobsDecoder()
    good = encode_transfer(bytes(128))
    assert dec.feed(b"\x05\x01\x00" + good) == [bytes(128)]  # \x05 claims 4 bytes, only 1 follows
    assert dec.errors == 1
    assert dec.feed(good[:10]) == [] and dec.feed(good[10:]) == [bytes(128)]
    assert dec.feed(b"\x00\x00") == []  # idle delimiters


def test_memory_pair_models_chip_select_faults() -> None:
    a, b = memory_pair()
    a.mangle = lambda t: [t[:127], t + b"\0", t, t]
    a.send(bytes(128))
    assert [len(t) for t in iter(lambda: b.recv(0), None)] == [127, 129, 128, 128]


def test_tcp_peer_going_away_is_an_adapter_error_not_a_crash() -> None:
    server = TcpListenAdapter("127.0.0.1", 0, timeout=2.0)
    host, port = server.address
    s = socket.create_connection((host, port))
    assert server.accept(2.0)
    s.close()
    with pytest.raises(LinkLostError):  # reported once, as a typed adapter error
        server.recv(0.5)
    assert server.recv(0.1) is None  # then the listener waits for a new peer
    s2 = socket.create_connection((host, port))
    assert server.accept(2.0)
    s2.sendall(encode_transfer(bytes(128)))
    assert server.recv(1.0) == bytes(128)
    s2.close()
    server.close()


def test_pty_peer_leaving_is_link_lost_and_writes_never_block() -> None:
    """A host that exits (closes the slave) or stops reading ends in LinkLostError within the
    write timeout, never a write that blocks forever."""
    import os
    import time

    from eyeq_spi.phy.pty import PtyAdapter

    a = PtyAdapter()
    fd = os.open(a.path, os.O_RDWR | os.O_NOCTTY)
    assert a.accept(1.0)
    a.write_timeout = 0.3
    t0 = time.monotonic()
    with pytest.raises(LinkLostError):
        for _ in range(10_000):  # the peer never reads: the pty buffer fills up
            a.send(bytes(128))
    assert time.monotonic() - t0 < 3.0
    os.close(fd)
    a.close()


def test_one_address_grammar_listen_and_connect() -> None:
    """--listen tcp://HOST:PORT and --port tcp://HOST:PORT meet; pyserial's socket:// means the
    same; bad addresses are typed errors."""
    from eyeq_spi.phy.address import parse_connect, parse_listen
    from eyeq_spi.phy.base import open_listener

    server = open_listener("tcp://127.0.0.1:0", timeout=5.0)
    url = server.url  # type: ignore[attr-defined]
    assert url.startswith("tcp://127.0.0.1:")
    client = open_url(url)
    try:
        client.send(b"\x01\x00\x02")
        got = None
        for _ in range(100):
            got = server.recv(0.05)
            if got:
                break
        assert got == b"\x01\x00\x02"
    finally:
        client.close()
        server.close()
    assert parse_connect(url).url == "socket://" + url[len("tcp://"):]
    assert parse_connect("socket://h:1").display == "tcp://h:1"
    assert parse_listen("tcp://[::1]:0").host == "::1"
    for bad in ("tcp://h:x", "tcp://h:70000", "udp://h:1", "h:1", "listen://h:1", "socket://h:1"):
        with pytest.raises(AdapterError):
            parse_listen(bad)
    with pytest.raises(AdapterError):
        parse_connect("tcp://h:0")  # nobody listens on port 0
