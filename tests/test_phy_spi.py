"""The SPI adapter (eyeq_spi/phy/spi.py) over in-memory channels, the bench file and URL pairs
(eyeq_spi/phy/bench.py) and the doctor's diagnosis and verdict (eyeq_spi/phy/doctor.py).

No driver and no simulated wire here: the channels are lists behind the adapter's
MasterChannel/SlaveChannel protocols. The adapter's reader and writer threads are real, so each
test waits for them with a short bound (well under a second)."""

from __future__ import annotations

import queue
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest

from eyeq_spi.errors import AdapterError, LinkLostError, UsageError
from eyeq_spi.phy.address import is_spi
from eyeq_spi.phy.bench import parse_side
from eyeq_spi.phy.doctor import Tally, diagnose, frame_pattern, judge, verdict_line
from eyeq_spi.phy.spi import REVERSED, SpiAdapter, SpiSettings
from tests.waiting import wait_until

WAIT = 1.0


class Master:
    """A master channel that keeps what it clocks out (``fail``: the driver failing)."""

    def __init__(self, lsb_first: bool = False) -> None:
        self.name = "mem-master"
        self.lsb_first = lsb_first
        self.wire: queue.Queue[bytes] = queue.Queue()
        self.fail = False

    def write(self, transfer: bytes) -> None:
        if self.fail:
            raise AdapterError("unplugged")
        self.wire.put(transfer)

    def close(self) -> None:
        pass


class Slave:
    """A slave channel fed by the test (``fail``: the driver failing)."""

    def __init__(self, lsb_first: bool = False) -> None:
        self.name = "mem-slave"
        self.lsb_first = lsb_first
        self.overruns = 0
        self.lines: queue.Queue[bytes] = queue.Queue()
        self.fail = False

    def read(self, timeout: float) -> bytes | None:
        if self.fail:
            raise AdapterError("unplugged")
        try:
            return self.lines.get(timeout=min(timeout, 0.01))
        except queue.Empty:
            return None

    def close(self) -> None:
        pass


def adapter(master: Master | None = None, slave: Slave | None = None,
            clock: Callable[[], float] = time.monotonic, **settings: object) -> SpiAdapter:
    return SpiAdapter(master or Master(), slave or Slave(), SpiSettings(**settings),  # type: ignore[arg-type]
                      clock=clock)


def frame(n: int) -> bytes:
    return bytes([n]) * 128


def test_a_transfer_goes_out_on_the_master_and_comes_in_from_the_slave() -> None:
    master, slave = Master(), Slave()
    with adapter(master, slave) as side:
        side.send(frame(1))
        assert master.wire.get(timeout=WAIT) == frame(1)
        slave.lines.put(frame(2))
        assert side.recv(WAIT) == frame(2)
        assert side.recv(0) is None


def test_a_short_transfer_stays_short_so_the_link_counts_it() -> None:
    slave = Slave()
    with adapter(slave=slave) as side:
        slave.lines.put(frame(3)[:60])  # chip select rose after 60 bytes
        assert side.recv(WAIT) == frame(3)[:60]


@pytest.mark.parametrize("hardware", [False, True])
def test_lsb_first_by_the_controller_or_by_the_table(hardware: bool) -> None:
    master, slave = Master(lsb_first=hardware), Slave(lsb_first=hardware)
    data = bytes(range(128))
    with adapter(master, slave, bit_order="lsb_first") as side:
        side.send(data)
        # a controller that can sends our bytes as they are; otherwise the adapter reverses
        # each byte, so that an MSB-first controller puts LSB-first bits on the wire
        assert master.wire.get(timeout=WAIT) == (data if hardware else data.translate(REVERSED))
        slave.lines.put(data if hardware else data.translate(REVERSED))
        assert side.recv(WAIT) == data


def test_transfers_the_link_does_not_take_in_time_are_counted_overruns() -> None:
    slave = Slave()
    with adapter(slave=slave, queue=4) as side:
        assert side.accept(0)  # the adapter's threads run from its first use
        for n in range(10):
            slave.lines.put(frame(n))
        # the reader takes every transfer; the link takes none: 4 queued, 6 overruns
        wait_until(lambda: side.overruns == 6, WAIT, "6 overruns counted")
        assert side.line_report()["overruns"] == 6
        assert [side.recv(WAIT) for _ in range(4)] == [frame(n) for n in range(4)]


def test_the_reply_latency_runs_from_the_slave_read_to_the_master_write() -> None:
    slave = Slave()
    with adapter(slave=slave) as side:
        slave.lines.put(frame(1))
        assert side.recv(WAIT) == frame(1)
        side.send(frame(9))  # the ACK
        side.wait_sent()
        assert side.recv(0) is None
        side.send(frame(8))  # a later frame answers a timer, not the frame received
        side.wait_sent()
        report = side.line_report()
        assert report["reply_latency_ms"]["n"] == 1
        assert 0 <= report["reply_latency_ms"]["max"] < 1000


def test_a_peer_heard_and_then_silent_is_gone_once_and_its_next_transfer_is_a_new_peer() -> None:
    now = [0.0]
    slave = Slave()
    with adapter(slave=slave, clock=lambda: now[0], silence=1.0) as side:
        assert side.accept(0) and side.recv(0) is None  # nothing heard yet: no silence
        now[0] = 5.0
        assert side.recv(0) is None
        slave.lines.put(frame(1))
        assert side.recv(WAIT) == frame(1)
        now[0] = 6.5
        with pytest.raises(LinkLostError, match="nothing from the peer"):
            side.recv(0)
        assert side.recv(0) is None  # said once
        assert not side.accept(0)
        slave.lines.put(frame(2))
        now[0] = 7.0
        wait_until(lambda: side.accept(0), WAIT, "the new peer's transfer read")
        assert side.recv(WAIT) == frame(2)


@pytest.mark.parametrize("which", ["master", "slave"])
def test_a_driver_that_fails_loses_the_link_for_good(which: str) -> None:
    master, slave = Master(), Slave()
    with adapter(master, slave) as side:
        assert side.accept(0)
        if which == "master":
            master.fail = True
            side.send(frame(1))  # handed over; the writer finds the driver gone
            with pytest.raises(LinkLostError, match="unplugged"):
                side.wait_sent()
        else:
            slave.fail = True
            with pytest.raises(LinkLostError, match="unplugged"):
                side.recv(WAIT)
        with pytest.raises(LinkLostError):
            side.send(frame(2))
        assert not side.accept(0)


def test_bad_settings_are_refused() -> None:
    for bad in ({"mode": 4}, {"bit_order": "middle"}, {"queue": 0}, {"silence": 0.0}):
        with pytest.raises(AdapterError):
            SpiSettings(**bad)  # type: ignore[arg-type]


# -- naming a side ---------------------------------------------------------------------------
def test_a_url_pair_names_master_then_slave_with_the_seed_settings() -> None:
    side = parse_side("spidev:///dev/spidev0.0,ft4222://FT1")
    assert (side.master, side.slave) == ("spidev:///dev/spidev0.0", "ft4222://FT1")
    assert (side.settings.mode, side.settings.clock_hz) == (1, 10_000_000)  # §6
    assert is_spi("ft4222://0,ft4222://1") and is_spi("rig.toml")
    assert not is_spi("tcp://127.0.0.1:5000") and not is_spi("/dev/ttyUSB0")


@pytest.mark.parametrize("text", ["spidev:///dev/spidev0.0", "ft4222://1,tcp://x:1",
                                  "ft4222://,ft4222://2", "a,b,c"])
def test_a_side_that_is_not_two_spi_channels_is_a_usage_error(text: str) -> None:
    with pytest.raises(UsageError):
        parse_side(text)


def test_a_bench_file_names_the_channels_and_the_settings(tmp_path: Path) -> None:
    path = tmp_path / "bench.toml"
    path.write_text('[master]\nurl = "ft4222://A"\n[slave]\nurl = "spidev:///dev/spidev1.0"\n'
                    '[spi]\nmode = 0\nbit_order = "lsb_first"\ngap_us = 500\n'
                    'silence_ms = 250\n')
    side = parse_side(str(path))
    assert (side.master, side.slave) == ("ft4222://A", "spidev:///dev/spidev1.0")
    s = side.settings
    assert (s.mode, s.bit_order, s.gap, s.silence) == (0, "lsb_first", 0.0005, 0.25)


@pytest.mark.parametrize(("body", "says"), [
    ('[master]\nurl = "ft4222://A"\n', "[slave] url"),
    ('[master]\nurl = "ft4222://A"\n[slave]\nurl = "ft4222://B"\n[spi]\nmdoe = 1\n',
     "unknown [spi] key 'mdoe'"),
    ('[master]\nurl = "ft4222://A"\n[slave]\nurl = "ft4222://B"\n[spi]\nmode = "1"\n',
     "wrong type"),
    ('[master]\nurl = "ft4222://A"\n[slave]\nurl = "ft4222://B"\n[spi]\nmode = 7\n',
     "SPI mode"),
    ('[master]\nurl = "tcp://x:1"\n[slave]\nurl = "ft4222://B"\n', "master channel"),
    ("[master\n", "cannot read bench file"),
    ('[wires]\nurl = "x"\n', "unknown table [wires]"),
])
def test_a_bad_bench_file_is_a_usage_error_naming_the_file(tmp_path: Path, body: str,
                                                           says: str) -> None:
    path = tmp_path / "bench.toml"
    path.write_text(body)
    with pytest.raises(UsageError, match=r"bench\.toml") as err:
        parse_side(str(path))
    assert says in str(err.value)


# -- the doctor ------------------------------------------------------------------------------
def test_the_doctor_tells_what_went_wrong_with_a_frame() -> None:
    sent = frame_pattern(7)
    value = int.from_bytes(sent, "big")
    assert diagnose(sent, sent) == "intact"
    assert diagnose(sent, None) == "lost"
    assert diagnose(sent, sent[:50]) == "short"
    assert diagnose(sent, sent.translate(REVERSED)) == "bit_order"
    assert diagnose(sent, (value >> 1).to_bytes(128, "big")) == "mode"
    assert diagnose(sent, bytes(128)) == "corrupt"
    assert frame_pattern(7) != frame_pattern(8) != frame_pattern(8, reply=True)


def test_the_doctor_says_fit_only_within_the_ack_timeout() -> None:
    fast = Tally(Counter({"intact": 400}), [0.0008] * 200, [0.002] * 200)
    report = judge(fast, wiring="loop", adapters=["x"])
    assert report["fit"] and verdict_line(report).startswith("FIT for a live EyeQ")
    slow = Tally(Counter({"intact": 400}), [0.0008] * 200, [0.002] * 199 + [0.012])
    report = judge(slow, wiring="loop", adapters=["x"])
    assert not report["fit"]
    assert "not under the 10 ms ackTimeout" in verdict_line(report)
    swapped = Tally(Counter({"bit_order": 10}), [], [])
    assert "bit order" in verdict_line(judge(swapped, wiring="pair", adapters=["x", "y"]))
