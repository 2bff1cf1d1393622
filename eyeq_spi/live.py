"""The live runs in real time over a real adapter: :func:`serve` (``eyeq-spi sim``) and
:func:`drive` (``eyeq-spi host``), each returning one run summary (:mod:`eyeq_spi.summary`).
Ctrl-C ends a run cleanly: the summary says ``interrupted``."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from typing import Any

from eyeq_spi.errors import AdapterError, LinkLostError
from eyeq_spi.host.host import HostEmulator
from eyeq_spi.runner.realtime import RealTimeRunner
from eyeq_spi.runner.sched import realtime
from eyeq_spi.sim.eyeq import SimulatedEyeQ
from eyeq_spi.summary import (
    LeftAtLinkLoss,
    RunningVision,
    SimSessions,
    host_summary,
    new_connection,
    sim_summary,
)

Tap = Callable[[str, float, bytes], None]
"""``tap(kind, t, transfer)``: every transfer, ``kind`` "tx" or "rx", as the runner sees it."""


def capture_tap(writer: Any, start: float, tx: str, rx: str) -> Tap | None:
    """A tap writing both channels to a capture writer (``tx`` and ``rx`` name our own and the
    peer's direction), with times since ``start``; None without a writer."""
    if writer is None:
        return None

    def tap(kind: str, time_s: float, transfer: bytes) -> None:
        writer.write(tx if kind == "tx" else rx, time_s - start, transfer)

    return tap


def _close(*things: Any) -> None:
    """Close each of ``things`` that is there, in order."""
    for thing in things:
        if thing is not None:
            thing.close()


def _heard(sim: SimulatedEyeQ, tap: Tap | None) -> tuple[Tap, list[int | None]]:
    """A tap that notes the link's send failures whenever the host is heard (then calls
    ``tap``), and the cell it notes them in (:meth:`SimSessions.add`)."""
    cell: list[int | None] = [None]

    def noted(kind: str, at: float, transfer: bytes) -> None:
        if kind == "rx":  # (a power-up makes a new link: looked up each time)
            cell[0] = sim.conn.link.counters.sendFailedErrorCounter
        if tap is not None:
            tap(kind, at, transfer)
    return noted, cell


def serve(eyeq: SimulatedEyeQ, adapter: Any, *, duration: float | None, accept_timeout: float,
          address: str, rt_priority: int = 0, capture: Any = None,
          clock: Callable[[], float] = time.monotonic) -> dict[str, Any]:
    """Serve one host after another on ``adapter`` until ``duration`` s end (None: until
    interrupted) or ``accept_timeout`` s pass without any host; every connection powers ``eyeq``
    up again, as the reset line would. Closes ``adapter`` and ``capture``."""
    t0, cpu0 = clock(), time.process_time()
    end = None if duration is None else t0 + duration
    sim: SimulatedEyeQ | None = None
    served = SimSessions(t0)  # one summary per host served
    interrupted = False
    rt = contextlib.ExitStack()  # real-time scheduling for the live run only
    scheduling = rt.enter_context(realtime(rt_priority))
    try:
        while end is None or clock() < end:
            if sim is None and clock() - t0 > accept_timeout:
                break
            wait = 0.5 if end is None else max(0.0, min(0.5, end - clock()))
            if not adapter.accept(wait):
                continue
            sim = eyeq
            runner = RealTimeRunner(sim, adapter)
            runner.tap, heard = _heard(sim, capture_tap(capture, t0, "e2h", "h2e"))
            sim.power_up(runner.clock())
            served.begin(sim)
            began = clock()
            lost = None
            not_taken = adapter.stats.left_at_link_loss
            try:
                runner.run(None if end is None else max(0.0, end - clock()))
            except LinkLostError as exc:
                lost = str(exc)
            finally:
                runner.close()
            served.add(sim, began=began - t0, ended=clock() - t0, link_lost=lost,
                       not_taken=adapter.stats.left_at_link_loss - not_taken,
                       failed_when_heard=heard[0])
    except KeyboardInterrupt:
        interrupted = True
    finally:
        _close(rt, adapter, capture)
    problem = None
    if not served.sessions:
        waited = accept_timeout if duration is None else min(accept_timeout, duration)
        problem = (f"no host connected within {waited:g} s" if not interrupted
                   else "interrupted before any host")
    return sim_summary(sim or eyeq, served.sessions, elapsed=clock() - t0, wall=clock() - t0,
                       cpu=time.process_time() - cpu0, interrupted=interrupted,
                       address=address, scheduling=scheduling, problem=problem)


def reopen(open_url: Callable[[], Any], until: float) -> Any:
    """``open_url()`` again and again until it answers or ``until`` (monotonic) passes; None if
    it never did."""
    while time.monotonic() < until:
        try:
            return open_url()
        except AdapterError:
            time.sleep(min(0.2, max(0.0, until - time.monotonic())))
    return None


def drive(host: HostEmulator, adapter: Any, *, duration: float, address: str,
          reopen_adapter: Callable[[float], Any] | None = None, exit_when_running: bool = False,
          rt_priority: int = 0, capture: Any = None,
          attach: Callable[[Any], Any] | None = None,
          on_step: Callable[[HostEmulator, float], None] | None = None) -> dict[str, Any]:
    """Run ``host`` against the EyeQ on ``adapter`` for ``duration`` s and judge it (Running
    Vision reached and held). ``reopen_adapter(until)``: a new adapter when the link is lost (None:
    give up), on which the bring-up runs again (a host that gave up starts its next ignition
    cycle). ``exit_when_running``: stop once in Running Vision. ``attach(runner)``: a CAN output
    (its ``summary()`` joins the result as ``can``). ``on_step(host, t)``: after every step.
    Closes ``adapter`` and ``capture`` and saves the host's NVM."""
    runner = RealTimeRunner(host, adapter)
    runner.tap = capture_tap(capture, runner.clock(), "h2e", "e2h")
    can_out = attach(runner) if attach is not None else None
    start, cpu0 = runner.clock(), time.process_time()
    end = start + duration
    host.start(start)
    vision = RunningVision()
    link_lost: str | None = None
    connections = 1
    left = LeftAtLinkLoss()  # what each lost connection left: its own, not the next one's
    interrupted = False
    rt = contextlib.ExitStack()  # real-time scheduling for the live run only
    scheduling = rt.enter_context(realtime(rt_priority))
    try:
        while runner.clock() < end:
            try:
                runner.step()
            except LinkLostError as exc:
                link_lost = str(exc)
                adapter.close()
                adapter = reopen_adapter(end) if reopen_adapter is not None else None
                if adapter is None:
                    break
                link_lost = None
                connections += 1
                runner.adapter = adapter
                new_connection(host, runner.clock(), left)
                vision.reset()  # judged again on the new connection
                continue
            now = runner.clock()
            if on_step is not None:
                on_step(host, now - start)
            vision.update(host, now - start)
            if exit_when_running and vision.since is not None:
                break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        _close(runner, rt, adapter)
        host.nvm.save()
        _close(capture, can_out)
    now = runner.clock()
    out = host_summary(host, side="host", elapsed=now - start, wall=now - start,
                       cpu=time.process_time() - cpu0, running_since=vision.since,
                       left_running=vision.left, link_lost=link_lost, connections=connections,
                       interrupted=interrupted, t0=start, address=address,
                       scheduling=scheduling, left=left if connections > 1 else None)
    if can_out is not None:
        out["can"] = can_out.summary()
    return out
