"""``eyeq-spi batch DIR --parquet OUT``: a fleet's captures into one partitioned Parquet
dataset, in this process, a process pool, or on Dask."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from eyeq_spi.errors import UsageError


def add_parser(sub: Any, name: str, help: str) -> None:
    from eyeq_spi.cli import options as opt

    parser = sub.add_parser(name, help=help,
                       description="Dissect every *.pcapng under DIR as dissect does "
                       "and write one Parquet dataset partitioned by capture and message "
                       "(OUT/capture=NAME/message=NAME/part-0.parquet). Prints one JSON "
                       "summary per capture. Exit 0 all captures read, 1 some could not be "
                       "read, 2 bad usage.")
    parser.add_argument("dir", metavar="DIR", help="a directory of captures (searched recursively) "
                   "or one capture")
    parser.add_argument("--parquet", required=True, metavar="OUT", help="dataset directory")
    opt.add_sw(parser, "SW release of the traffic (default newest)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--jobs", "-j", type=opt.limited("batch_jobs"), default=1, metavar="N",
                       help="captures at a time in local worker processes (default 1)")
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                       help="run the captures on this Dask scheduler (workers must see DIR "
                       "and OUT at the same paths)")
    where.add_argument("--local-cluster", type=opt.limited("local_cluster"), metavar="N",
                       help="run the captures on a Dask LocalCluster of N worker processes")


def run(args: argparse.Namespace) -> int:
    from eyeq_spi.dissect.fleet import run_fleet

    if args.scheduler and not args.scheduler.startswith(("tcp://", "tls://", "inproc://")):
        raise UsageError(f"--scheduler: a Dask address such as tcp://HOST:8786, "
                         f"not {args.scheduler!r}")
    from eyeq_spi.cli.progress import JobProgress

    # the summaries go to stdout at the end: nothing is written between them while it runs
    with JobProgress("batch", unit="captures") as bar:
        summaries = run_fleet(args.dir, args.parquet, sw=args.sw, jobs=args.jobs,
                              scheduler=args.scheduler, local_cluster=args.local_cluster,
                              progress=bar.update)
    for summary in summaries:
        sys.stdout.write(json.dumps(summary, separators=(",", ":")) + "\n")
    return 1 if any(s["error"] for s in summaries) else 0
