"""Run the suite: select cases, run the sessions they need (our tester against the
implementation under test), judge every selected case on the traces, return the results."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from eyeq_spi import __version__
from eyeq_spi.catalog.messages import catalog
from eyeq_spi.conformance.cases import SUITE_VERSION, cases_for
from eyeq_spi.conformance.judges.app import is_reply, ret_of
from eyeq_spi.conformance.judges.flow import QUIET_FOR
from eyeq_spi.conformance.judges.verdict import Context, Outcome, skip
from eyeq_spi.conformance.load import temper
from eyeq_spi.conformance.model import ALL_SESSIONS, Case
from eyeq_spi.conformance.mutants import build_eyeq, build_host
from eyeq_spi.conformance.play.eyeq import EyeqPlan, EyeqScript, TesterEyeQ, tester_config
from eyeq_spi.conformance.play.host import HostPlan, HostScript, TesterHost
from eyeq_spi.conformance.play.session import Session
from eyeq_spi.conformance.trace import Trace
from eyeq_spi.errors import AdapterError, EyeqError, UsageError
from eyeq_spi.host.host import HostConfig
from eyeq_spi.host.nvm import Nvm, NvmData
from eyeq_spi.phy.base import Adapter, open_url

HOST_SESSIONS = ("normal", "eeprom_bad", "boot_fail")


class EcuNvm(Nvm):
    """An in-memory NVM that survives the host's restart between ignition cycles."""

    def load(self) -> NvmData:
        return self.data


@dataclass(frozen=True)
class Result:
    case: Case
    outcome: Outcome

    def as_json(self) -> dict[str, Any]:
        case = self.case
        out = {"kind": "case", "id": case.id, "title": case.title, "section": case.section,
               "requirement": case.requirement, "decision": case.decision, "rule": case.rule,
               "verdict": self.outcome.verdict, "evidence": self.outcome.evidence}
        if self.outcome.advice:  # our recommendation beyond the seed: never a failure
            out["advice"] = self.outcome.advice
        return out


@dataclass(frozen=True)
class Header:
    """What a signed report states before its verdicts."""

    dut: str  # "eyeq" or "host"
    address: str
    sw_seen: str  # what the implementation under test reported of its release
    sw: str  # the release whose tables the suite played and decoded (--sw)
    tool: str
    suite: str
    date: str
    clock: str  # virtual (--builtin) or real time

    def as_json(self) -> dict[str, str]:
        """The JSON header: each row under its name in snake case, and ``dut``."""
        return {"kind": "header", "dut": self.dut,
                **{key.lower().replace(" ", "_"): value for key, value in self.rows()}}

    def rows(self) -> list[tuple[str, str]]:
        side = {"eyeq": "EyeQ (we played the host)", "host": "host (we played the EyeQ)"}
        return [("side under test", side[self.dut]), ("address", self.address),
                ("SW release seen", self.sw_seen), ("tables of release", self.sw),
                ("time", self.clock), ("tool", self.tool), ("suite", self.suite),
                ("date", self.date)]


@dataclass(frozen=True)
class Report:
    header: Header
    results: list[Result]


@dataclass
class Options:
    dut: str  # "eyeq" (we play the host) or "host" (we play the EyeQ)
    sw: str | None = None
    builtin: bool = False
    port: str | None = None  # --dut eyeq: pyserial URL of the EyeQ
    adapter: Adapter | None = None  # --dut host: a listener or pty the host connects to
    # --dut host --pty: closes the old adapter, opens a fresh pty for the next ignition cycle
    reopen: Callable[[], Adapter] | None = None
    accept_timeout: float = 30.0
    select: str | None = None  # -k EXPR
    mutant: str | None = None  # test-only: a broken variant of our own implementation
    host_plan: HostPlan = field(default_factory=HostPlan)
    eyeq_plan: EyeqPlan = field(default_factory=EyeqPlan)
    progress: Callable[[str], None] | None = None
    # a progress bar's update: steps done of all (each session, then the judging)
    steps: Callable[[int, int], None] | None = None
    # called before judging (the CLI leaves SCHED_FIFO there: judging is CPU-bound)
    sessions_done: Callable[[], None] | None = None

    def __post_init__(self) -> None:
        """Our own implementations answer at once: shorter watches keep the mutant matrix fast
        (every rate still gets >= 9 periods); the caller may still change the plans."""
        if self.builtin:
            hp, ep = self.host_plan, self.eyeq_plan
            hp.bring_up_timeout = hp.mode_timeout = 10.0
            hp.steady, hp.mode_hold = 0.8, 0.5
            ep.steady, ep.stale_for, ep.after_reset = 0.8, 0.5, 2.5
            # the eeprom_bad watch: HOST-EEPROM-BAD's window (the script adds 0.05 s after it)
            ep.boot_fail_watch, ep.eeprom_watch = 3.0, QUIET_FOR


_TOKEN = re.compile(r"\(|\)|[^\s()]+")


def selector(expr: str | None) -> Callable[[Case], bool]:
    """``-k``: words match case-insensitively against ID, title, group and section; combine
    with ``and``, ``or``, ``not`` and parentheses (pytest's -k, without its keywords)."""
    if not expr:
        return lambda c: True
    words: list[str] = []

    def term(token: str) -> str:
        low = token.lower()
        if low in ("and", "or", "not", "(", ")"):
            return low
        if not re.fullmatch(r"[\w.\-:/]+", token):
            raise UsageError(f"-k: unexpected {token!r}")
        words.append(low)
        return f"_w[{len(words) - 1}] in _h"

    try:
        code = compile(" ".join(map(term, _TOKEN.findall(expr))), "<-k>", "eval")
    except SyntaxError:
        raise UsageError(f"-k: cannot parse {expr!r}") from None

    def match(case: Case) -> bool:
        hay = " ".join((case.id, case.title, case.group, case.section)).lower()
        return bool(eval(code, {"__builtins__": {}}, {"_w": words, "_h": hay}))
    return match


def select_cases(opts: Options) -> list[Case]:
    keep = selector(opts.select)
    chosen = [c for c in cases_for(opts.dut, opts.sw) if keep(c)]
    if not chosen:
        raise UsageError(f"-k {opts.select!r} selects no case for --dut {opts.dut}")
    return chosen


def run(opts: Options) -> list[Result]:
    return run_report(opts).results


def run_report(opts: Options) -> Report:
    """Run the suite: the verdicts, under the header a signed report needs."""
    date = datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    address = _address(opts)
    cases = select_cases(opts)
    wanted = {n for c in cases for n in c.needs}
    ctx = Context(opts.dut, realtime=not opts.builtin)
    sessions: list[str] = ["main"]
    if opts.dut != "eyeq":
        needed = {c.session_for("host") for c in cases}
        if ALL_SESSIONS in needed:
            needed |= {"normal", "eeprom_bad"}
        sessions = [s for s in HOST_SESSIONS if s in needed]
    total = len(sessions) + 1
    step = opts.steps or (lambda *_: None)
    step(0, total)
    for number, name in enumerate(sessions):
        tr = (_eyeq_session(opts, wanted, ctx) if opts.dut == "eyeq"
              else _host_session(opts, name, wanted, ctx, first=number == 0))
        if tr is not None:
            ctx.traces[name] = tr
        step(number + 1, total)
    if opts.sessions_done is not None:
        opts.sessions_done()
    out = [Result(c, _judge(c, ctx)) for c in cases]
    step(total, total)
    key = catalog().sw(opts.sw)
    suite = (f"{SUITE_VERSION}, {len(out)} of its {len(cases_for(opts.dut, opts.sw))} cases for "
             f"{'an EyeQ' if opts.dut == 'eyeq' else 'a host'}")
    header = Header(opts.dut, address, _sw_seen(ctx, key), key, f"eyeq-spi {__version__}",
                    suite, date, "virtual (--builtin)" if opts.builtin else "real")
    return Report(header, out)


def _address(opts: Options) -> str:
    if opts.builtin:
        variant = f", variant {opts.mutant}" if opts.mutant else ""
        return f"built-in: our own {'simulated EyeQ' if opts.dut == 'eyeq' else 'host'}{variant}"
    if opts.dut == "eyeq":
        return opts.port or "-"
    adapter = opts.adapter
    where = getattr(adapter, "url", None) or getattr(adapter, "path", None)
    if opts.reopen is not None:
        return f"a pty per ignition cycle, the first {where}"
    return str(where or "-")


def _sw_seen(ctx: Context, key: str) -> str:
    """The release the implementation under test reported: an EyeQ's Get EyeQ Versions reply."""
    if ctx.dut == "host":
        return f"none (a host reports no release on the SPI link; we played an EyeQ of {key})"
    tr = ctx.traces.get("main")
    replies = [reply for reply in (tr.dut_msgs("GetEyeQVersions") if tr is not None else [])
               if is_reply(reply) and ret_of(reply) == 0 and reply.fields]
    if not replies:
        return "not reported (no Get EyeQ Versions reply with ret 0)"
    reply, fields = replies[0], replies[0].fields
    return (f"EyeQ SW {fields.get('eyeqSwVersionMajor')}.{fields.get('eyeqSwVersionMinor')}, "
            f"MESP API {fields.get('apiVersionMajor')}.{fields.get('apiVersionMinor')} "
            f"(Get EyeQ Versions reply #{reply.indices[-1]})")


def _judge(case: Case, ctx: Context) -> Outcome:
    name = case.session_for(ctx.dut)
    if name == ALL_SESSIONS:
        if not ctx.traces:
            return skip("no session could run")
        return temper(case, case.judge(ctx, dict(ctx.traces)), list(ctx.traces.values()))
    tr = ctx.traces.get(name)
    if tr is None:
        return skip(f"session {name!r} did not run (the host under test did not connect)")
    return temper(case, case.judge(ctx, tr), [tr])


def _say(opts: Options, text: str) -> None:
    if opts.progress is not None:
        opts.progress(text)


# -- the EyeQ under test: one session ---------------------------------------------------------
def _eyeq_session(opts: Options, wanted: set[str], ctx: Context) -> Trace:
    plan = opts.host_plan
    trace = Trace("eyeq", opts.sw, realtime=ctx.realtime)
    tester = TesterHost(HostConfig(sw=opts.sw), hold=plan.hold_veh)
    if opts.builtin:
        session = Session(trace, tester, dut=build_eyeq(opts.mutant, opts.sw))
        session.dut.power_up(0.0)
    else:
        if opts.port is None:
            raise UsageError("--dut eyeq needs --port URL (or --builtin)")
        tester.warm_up()  # no first-time codec build may stall our loop (load.py)
        session = Session(trace, tester, adapter=open_url(opts.port))
    _say(opts, "session main: we play the host")
    try:
        HostScript(session, tester, plan, wanted).run()
    finally:
        session.finish()
        if session.adapter is not None:
            session.adapter.close()
    return trace


# -- the host under test: one session per ignition cycle --------------------------------------
def _host_session(opts: Options, name: str, wanted: set[str], ctx: Context, *,
                  first: bool) -> Trace | None:
    plan = opts.eyeq_plan
    trace = Trace("host", opts.sw, realtime=ctx.realtime)
    tester = TesterEyeQ(tester_config(name, opts.sw, fast=opts.builtin), trace)
    if opts.builtin:
        nvm = ctx.builtin.setdefault("nvm", EcuNvm())  # one ECU: its NVM outlives the cycle
        dut = build_host(opts.mutant, opts.sw, tester.reset_line, nvm)
        session = Session(trace, tester, dut=dut)
        dut.start(0.0)
    else:
        adapter = opts.adapter
        if adapter is None:
            raise UsageError("--dut host needs --listen tcp://HOST:PORT or --pty (or --builtin)")
        accept: Any = getattr(adapter, "accept", None)
        if not first:
            drop: Any = getattr(adapter, "drop", None)
            if drop is not None:
                drop()  # end the ignition cycle: the host under test reconnects
            elif opts.reopen is not None:
                adapter = opts.adapter = opts.reopen()  # the host opens the new pty
                accept = getattr(adapter, "accept", None)
            else:
                return None  # nothing can end the host's ignition cycle
        where = getattr(adapter, "url", None) or getattr(adapter, "path", None)
        _say(opts, f"session {name}: waiting up to {opts.accept_timeout:g} s for the host to "
             f"connect" + (f" to {where}" if where else ""))
        if accept is not None and not accept(opts.accept_timeout):
            if first:
                raise AdapterError(f"the host under test did not connect within "
                                   f"{opts.accept_timeout} s")
            _say(opts, f"session {name}: the host did not connect within "
                 f"{opts.accept_timeout:g} s; the cases judged on this session are skipped")
            return None
        tester.warm_up()  # no first-time codec build may stall our loop (load.py)
        session = Session(trace, tester, adapter=adapter)
    _say(opts, f"session {name}: we play the EyeQ")
    try:
        EyeqScript(session, tester, plan, name, wanted).run()
    except EyeqError as exc:
        if first:
            raise
        trace.mark(session.now, "session_error", error=str(exc))
    finally:
        session.finish()
    return trace
