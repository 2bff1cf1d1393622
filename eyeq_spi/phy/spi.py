"""One side of a link on real SPI lines: two channels (seed 004 §5), a byte mover under the link.

:class:`SpiAdapter` sends each transfer chip-select-framed on our master channel and returns what
the peer clocked into our slave channel (a short one stays short: decision L8). It adds the bit
order on the wire, the chip-select gap, a reader and a writer thread (the link's loop never waits
for a USB round trip), the end of a silent peer and the counted overruns and reply latency
(docs/bench.md). The drivers sit behind :class:`MasterChannel` and :class:`SlaveChannel`."""

from __future__ import annotations

import contextlib
import os
import queue
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from eyeq_spi.errors import AdapterError, LinkLostError
from eyeq_spi.phy.base import Adapter

FRAME_LEN = 128  # §6: a frame ends after 128 bytes or at the rising edge of chip select
BIN_S = 1e-5  # reply latency histogram: 10 µs bins, as the run summary's ACK latency
# The reader thread hands a transfer to the link's thread through the interpreter lock; at
# Python's default 5 ms switch interval a busy link thread (encoding a burst) could hold a
# received frame for half the peer's ackTimeout. While an SPI adapter is open, the interpreter
# switches threads at least this often.
SWITCH_INTERVAL = 0.0002
DROP_SILENCES = 1.5  # drop(): silent this many of the peer's silence limits, to be sure


def _reverse_bits(value: int) -> int:
    return int(f"{value:08b}"[::-1], 2)


# what an LSB-first wire carries for each byte an MSB-first controller shifts out, and back
REVERSED = bytes(_reverse_bits(b) for b in range(256))


@dataclass(frozen=True)
class SpiSettings:
    """How a channel drives or samples the lines: clock (Hz), SPI mode (CPOL*2 + CPHA),
    ``bit_order`` of each byte on the wire, ``gap`` (s of chip select high between two master
    transfers), ``queue`` (received transfers held for the link before one is an overrun),
    ``silence`` (s without a transfer from a peer that was heard: it is gone)."""

    clock_hz: int = 10_000_000
    mode: int = 1
    bit_order: str = "msb_first"
    gap: float = 0.0
    queue: int = 1024
    silence: float = 1.0

    def __post_init__(self) -> None:
        if self.mode not in (0, 1, 2, 3):
            raise AdapterError(f"SPI mode must be 0..3, not {self.mode}")
        if self.bit_order not in ("msb_first", "lsb_first"):
            raise AdapterError(f"bit order must be msb_first or lsb_first, not "
                               f"{self.bit_order!r}")
        if self.clock_hz <= 0 or self.gap < 0 or self.queue < 1 or self.silence <= 0:
            raise AdapterError("clock, gap, queue and silence must be positive")


class MasterChannel(Protocol):
    """A driver's master side: ``write`` clocks one transfer out between one falling and one
    rising edge of chip select; ``lsb_first`` says whether the controller itself sends each
    byte least significant bit first (else the adapter reverses the bits)."""

    name: str
    lsb_first: bool

    def write(self, transfer: bytes) -> None: ...

    def close(self) -> None: ...


class SlaveChannel(Protocol):
    """A driver's slave side: ``read`` blocks until the master has clocked a transfer in (the
    bytes between chip select falling and rising, at most ``FRAME_LEN`` per transfer) and
    returns it, or None after ``timeout`` s; ``overruns``: transfers the driver says it lost."""

    name: str
    lsb_first: bool
    overruns: int

    def read(self, timeout: float) -> bytes | None: ...

    def close(self) -> None: ...


class ReplyLatency:
    """Slave read -> master write latencies in 10 µs bins (what the peer's ackTimeout sees)."""

    def __init__(self) -> None:
        self.hist: Counter[int] = Counter()

    def add(self, seconds: float) -> None:
        self.hist[int(seconds / BIN_S)] += 1

    def summary(self) -> dict[str, float | int]:
        """``n`` and the p50, p99, p99.9 and max in ms."""
        count = sum(self.hist.values())
        if not count:
            return {"n": 0}
        out: dict[str, float | int] = {"n": count}
        bins = sorted(self.hist.items())
        for name, share in (("p50", 0.5), ("p99", 0.99), ("p99_9", 0.999)):
            seen, rank = 0, share * count
            for slot, hits in bins:
                seen += hits
                if seen >= rank:
                    out[name] = round(slot * BIN_S * 1e3, 2)
                    break
        out["max"] = round(bins[-1][0] * BIN_S * 1e3, 2)
        return out


class SpiAdapter(Adapter):
    """One side of a link over a master channel and a slave channel (see the module doc).
    ``clock``: the monotonic clock the latencies are read on."""

    def __init__(self, master: MasterChannel, slave: SlaveChannel, settings: SpiSettings, *,
                 name: str = "", clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self.master = master
        self.slave = slave
        self.settings = settings
        self.name = name or f"{master.name}+{slave.name}"
        self.clock = clock
        self.reply = ReplyLatency()
        self.overruns = 0  # transfers dropped because the link did not take them in time
        self.last_arrival = 0.0  # the clock when the transfer ``recv`` returned last was read
        self._wanted_lsb = settings.bit_order == "lsb_first"
        self._ready: queue.Queue[tuple[float, bytes]] = queue.Queue(settings.queue)
        self._lost: str | None = None  # the channels failed: for good
        self._heard: float | None = None  # when the peer's last transfer was read
        self._quiet = False  # the peer went silent: the next transfer is a new peer
        self._last_write = float("-inf")
        self._pending_reply: float | None = None  # arrival of the transfer taken last
        self._stop = threading.Event()
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(min(SWITCH_INTERVAL, self._switch_interval))
        self._reader = threading.Thread(target=self._read_loop, name=f"spi-slave {slave.name}",
                                        daemon=True)
        self._outgoing: queue.SimpleQueue[tuple[bytes, float | None] | None] = (
            queue.SimpleQueue())
        self._written = threading.Condition()
        self._queued = self._done = 0
        self._writer = threading.Thread(target=self._write_loop,
                                        name=f"spi-master {master.name}", daemon=True)
        self._started = False
        self._policy: tuple[int, int] | None = None

    @property
    def url(self) -> str:
        return self.name

    def accept(self, timeout: float | None = None) -> bool:
        """A peer on the lines: at once on a fresh adapter (the lines are there, whoever is
        on them), and after a peer went silent as soon as a transfer comes again (within
        ``timeout`` s, None: at once or not at all). False once the channels failed."""
        self._start()
        end = time.monotonic() + (timeout or 0.0)
        while self._quiet and self._ready.empty():
            if self._lost is not None or time.monotonic() >= end:
                return False
            time.sleep(0.01)
        self._quiet = False
        return self._lost is None

    def drop(self) -> None:
        """End the peer's session the only way SPI lines can (they have no hang-up): say nothing
        for longer than ``silence`` and drop what it sends meanwhile; then :meth:`accept` takes
        the lines at once (a host that starts over waits for the EyeQ's boot status)."""
        self._start()
        with contextlib.suppress(LinkLostError):
            self.wait_sent()
        end = self.clock() + DROP_SILENCES * self.settings.silence
        while (left := end - self.clock()) > 0:
            with contextlib.suppress(queue.Empty):
                self._ready.get(timeout=min(0.05, left))
        self._heard, self._quiet, self._pending_reply = None, False, None

    def _start(self) -> None:
        """Start the reader and writer threads on first use, at the scheduling policy the run's
        loop took by then (``--rt-priority``; each thread takes it itself, as a policy taken
        with SCHED_RESET_ON_FORK is not inherited)."""
        if not self._started:
            self._started = True
            self._policy = _policy_of_caller()
            self._reader.start()
            self._writer.start()

    # -- the slave channel ----------------------------------------------------------------
    def _read_loop(self) -> None:
        _take_policy(self._policy)
        while not self._stop.is_set():
            try:
                transfer = self.slave.read(0.1)
            except (AdapterError, OSError) as exc:
                self._lost = f"{self.slave.name}: {exc}"
                return
            if transfer is None or self._stop.is_set():
                continue
            if self.slave.lsb_first != self._wanted_lsb:
                transfer = transfer.translate(REVERSED)
            try:
                self._ready.put_nowait((self.clock(), transfer))
            except queue.Full:
                self.overruns += 1

    def _recv_internal(self, timeout: float | None) -> bytes | None:
        self._start()
        try:
            arrived, transfer = (self._ready.get_nowait() if not timeout
                                 else self._ready.get(timeout=timeout))
        except queue.Empty:
            if self._lost is not None:
                raise LinkLostError(f"link lost: {self._lost}") from None
            if self._heard is not None and self.clock() - self._heard > self.settings.silence:
                self._heard, self._quiet = None, True
                raise LinkLostError(f"link lost: nothing from the peer on {self.slave.name} "
                                    f"for {self.settings.silence:g} s") from None
            # the last transfer taken made no reply before the link asked for more (an ACK
            # received): a later write answers a timer, not it
            self._pending_reply = None
            return None
        self.last_arrival = self._heard = arrived
        self._pending_reply = arrived
        return transfer

    # -- the master channel ---------------------------------------------------------------
    def _send_internal(self, transfer: bytes) -> None:
        """Hand ``transfer`` to the writer thread: the link's loop never waits for a USB
        round trip (it goes on reading ACKs and sending what falls due)."""
        self._start()
        if self._lost is not None:
            raise LinkLostError(f"link lost: {self._lost}")
        if self.master.lsb_first != self._wanted_lsb:
            transfer = transfer.translate(REVERSED)
        with self._written:
            self._queued += 1
        self._outgoing.put((transfer, self._pending_reply))
        self._pending_reply = None

    def _write_loop(self) -> None:
        _take_policy(self._policy)
        while (item := self._outgoing.get()) is not None:
            transfer, answers = item
            wait = self._last_write + self.settings.gap - self.clock()
            if wait > 0:
                _pause(wait)
            if self._lost is None:
                try:
                    self.master.write(transfer)
                except (AdapterError, OSError) as exc:
                    self._lost = f"{self.master.name}: {exc}"
            done = self._last_write = self.clock()
            if answers is not None and self._lost is None:
                self.reply.add(done - answers)
            with self._written:
                self._done += 1
                self._written.notify_all()

    def wait_sent(self, timeout: float = 1.0) -> float:
        """Wait until every transfer handed to ``send`` is on the wire; the clock when the
        last one was (:class:`LinkLostError` if the master channel failed)."""
        with self._written:
            self._written.wait_for(lambda: self._done >= self._queued, timeout)
        if self._lost is not None:
            raise LinkLostError(f"link lost: {self._lost}")
        return self._last_write

    def line_report(self) -> dict[str, Any]:
        """What the run summary reports of the lines: reply latency and overruns."""
        return {"adapter": self.name, "reply_latency_ms": self.reply.summary(),
                "overruns": self.overruns + self.slave.overruns}

    def _close_internal(self) -> None:
        self._stop.set()
        self._outgoing.put(None)
        if self._started:
            self._writer.join(1.0)  # what the link handed over goes out before the lines close
        for channel in (self.master, self.slave):
            with contextlib.suppress(AdapterError, OSError):
                channel.close()
        if self._started:
            self._reader.join(0.5)
        sys.setswitchinterval(self._switch_interval)


def _policy_of_caller() -> tuple[int, int] | None:
    """The calling thread's scheduling policy and priority (None where the OS has none)."""
    try:
        return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    except (AttributeError, OSError):
        return None


def _take_policy(policy: tuple[int, int] | None) -> None:
    """Run the calling thread at ``policy`` (as far as the OS grants it)."""
    if policy is None:
        return
    with contextlib.suppress(AttributeError, OSError):
        os.sched_setscheduler(0, policy[0], os.sched_param(policy[1]))


def _pause(seconds: float) -> None:
    """Chip select high for ``seconds``: sleep most of it, spin the last 200 µs (a sleep can
    overshoot by a scheduler tick)."""
    end = time.perf_counter() + seconds
    if seconds > 0.0005:
        time.sleep(seconds - 0.0002)
    while time.perf_counter() < end:
        pass


def report_text(spi: dict[str, Any], budget_ms: float) -> str:
    """The SPI lines of a run (``--port``/``--listen`` on an SPI side): the measured reply
    latency, slave read to master write (the ACK path the peer's ackTimeout, ``budget_ms``,
    judges), for the run summary's text."""
    lat = spi["reply_latency_ms"]
    line = f"  SPI {spi['adapter']}: overruns {spi['overruns']}, reply latency "
    if not lat["n"]:
        return line + "not measured (no transfer answered)"
    line += (f"p50 {lat['p50']:.2f} ms, p99 {lat['p99']:.2f} ms, p99.9 {lat['p99_9']:.2f} ms, "
             f"max {lat['max']:.2f} ms over {lat['n']} replies")
    if lat["p99_9"] >= budget_ms:
        line += f" (p99.9 at or above the {budget_ms:g} ms ackTimeout: this rig is too slow)"
    return line
