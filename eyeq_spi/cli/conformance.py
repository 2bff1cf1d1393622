"""``eyeq-spi conformance``: the protocol conformance suite against an EyeQ or a host under test
(or, with ``--builtin``, against our own in virtual time). Exit 0 when no case fails, 1 when one
does, 2 for usage or connection errors."""

from __future__ import annotations

import argparse
import shutil
import sys
from typing import TYPE_CHECKING, Any

from eyeq_spi.cli import args as ca
from eyeq_spi.errors import UsageError

if TYPE_CHECKING:
    from eyeq_spi.conformance.suite import Options


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import options as opt

    parser = sub.add_parser(
        name, help=help,
        description="Play the host against an EyeQ under test (--dut eyeq) or the EyeQ against "
        "a host under test (--dut host): one case per requirement of seed 004 and the protocol "
        "decisions, each with a verdict and its evidence. Exit 0 when no case fails, 1 when one "
        "fails, 2 for usage or connection errors.")
    parser.add_argument("--dut", choices=("eyeq", "host"), help="the implementation under test")
    where = parser.add_mutually_exclusive_group()
    ca.add_endpoints(parser, where,
                     port="--dut eyeq: connect to the EyeQ at tcp://HOST:PORT (socket:// too), "
                     "rfc2217://HOST:PORT, a tty/pty path, or our SPI channels "
                     "MASTER_URL,SLAVE_URL or a bench.toml (docs/bench.md)",
                     listen="--dut host: listen here (port 0: any free port); the host connects "
                     "(once per session); or our SPI channels, MASTER_URL,SLAVE_URL or a "
                     "bench.toml",
                     pty="--dut host: open a pty per ignition cycle, print each path; the host "
                     "opens each in turn")
    where.add_argument("--builtin", action="store_true",
                       help="test our own simulated EyeQ / host emulator, in virtual time")
    parser.add_argument("--list", action="store_true",
                   help="print every case (ID, DUT, seed section, requirement, decision, title)")
    parser.add_argument("-k", dest="select", metavar="EXPR",
                   help="select cases: words matched in ID/title/group/section, with and/or/not")
    opt.add_sw(parser, "SW release (default: newest)")
    opt.include(parser, opt.json_out("JSON Lines: a header object, one object per case, then the "
                                "summary with the overall verdict"))
    parser.add_argument("--junit", metavar="FILE", type=ca.output_file, help="write JUnit XML")
    parser.add_argument("--report", metavar="FILE.md|FILE.html", type=ca.output_file,
                   help="write a Markdown or HTML report")
    parser.add_argument("--accept-timeout", type=ca.number(0, 3600, lo_open=True, unit="s"),
                   default=30.0, help="seconds to wait for the host under test (default 30)")
    parser.add_argument("--mode-timeout", type=ca.number(0, 3600, lo_open=True, unit="s"),
                   default=None, help="seconds to wait for TAC/SPC results and mode changes")
    opt.include(parser, opt.rt_priority("our ACKs"))
    parser.add_argument("--mutant", help=argparse.SUPPRESS)  # test-only: a broken built-in variant


def _progress(args: argparse.Namespace) -> Any:
    """The session lines on stderr: always in a live run (whoever runs the implementation under
    test must see when each session waits for it), on a terminal only with --builtin."""
    if args.builtin and (args.json or not sys.stderr.isatty()):
        return None
    return lambda text: print(text, file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.conformance import report
    from eyeq_spi.conformance.cases import all_cases, cases_for
    from eyeq_spi.conformance.suite import Options, run_report, selector

    if args.list:
        keep = selector(args.select)
        cases = cases_for(args.dut, args.sw) if args.dut else all_cases(args.sw)
        print(report.listing([c for c in cases if keep(c)]))
        return 0
    if args.dut is None:
        raise UsageError("--dut eyeq or --dut host is required (or --list)")
    if args.mutant and not args.builtin:
        raise UsageError("--mutant works with --builtin only")
    opts = Options(dut=args.dut, sw=args.sw, builtin=args.builtin, select=args.select,
                   accept_timeout=args.accept_timeout, mutant=args.mutant,
                   progress=_progress(args))
    if args.mode_timeout is not None:
        opts.host_plan.mode_timeout = args.mode_timeout
    if not args.builtin and args.dut == "eyeq":
        if not args.port:
            raise UsageError("--dut eyeq needs --port URL (or --builtin): it connects to the "
                             "EyeQ under test")
        opts.port = args.port
    elif not args.builtin:
        opts.adapter = _listener(args, opts)
    import contextlib

    rt = contextlib.ExitStack()  # real-time scheduling for the live run only (runner/sched.py)
    if not args.builtin:
        from eyeq_spi.runner.sched import realtime

        scheduling = rt.enter_context(realtime(args.rt_priority))  # our stalls: the load gauge
        opts.sessions_done = rt.close  # judging is CPU-bound: ordinary scheduling again
        if opts.progress is not None and not args.json and sys.stderr.isatty():
            opts.progress(f"scheduling: {scheduling}")
    from eyeq_spi.cli.progress import JobProgress

    try:
        # the report goes to stdout at the end; the session lines print above the bar
        with JobProgress("conformance", unit="sessions + judging",
                         enabled=False if args.json else None) as bar:
            if opts.progress is not None:
                opts.progress = bar.print
            opts.steps = bar.update
            result = run_report(opts)
    finally:
        rt.close()  # never leave a caller (a test, a notebook) at SCHED_FIFO
        if opts.adapter is not None:
            opts.adapter.close()
    title = f"eyeq-spi conformance --dut {args.dut}" + (" --builtin" if args.builtin else "")
    if args.junit:
        report.write(args.junit, report.junit(result, f"eyeq-spi.conformance.{args.dut}"))
    if args.report:
        report.write_report(args.report, result, title)
    width = shutil.get_terminal_size((80, 24)).columns if sys.stdout.isatty() else None
    print(report.json_lines(result) if args.json else report.console(result, width=width))
    return report.exit_code(result.results)


def _listener(args: argparse.Namespace, opts: Options) -> Any:
    if args.pty:
        from eyeq_spi.phy.pty import PtyAdapter

        def fresh() -> Any:
            if opts.adapter is not None:
                opts.adapter.close()
            pty = PtyAdapter()
            print(f"PTY {pty.path}", file=sys.stderr, flush=True)  # stdout: the report
            return pty

        opts.reopen = fresh  # one pty per ignition cycle: the host opens each in turn
        return fresh()
    if not args.listen:
        raise UsageError("--dut host needs --listen tcp://HOST:PORT or --pty (or --builtin)")
    from eyeq_spi.phy.base import open_listener

    adapter: Any = open_listener(args.listen, timeout=args.accept_timeout)
    print(f"LISTEN {adapter.url}", file=sys.stderr, flush=True)
    return adapter
