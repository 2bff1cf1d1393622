"""Every argument is checked before any work: a table of bad invocations (exit 2, one line on
stderr naming the option and what it accepts, no traceback), and the names the checks accept."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from eyeq_spi.cli import args as cli_args
from eyeq_spi.cli import build_parser, main

HOST = ["host", "--port", "socket://127.0.0.1:5"]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    d = tmp_path_factory.mktemp("args")
    f = d / "one.hex"
    f.write_text("00" * 128 + "\n")
    (d / "dir").mkdir()
    return {"FILE": str(f), "DIR": str(d / "dir")}


# (argv, words the one stderr line must contain)
BAD: list[tuple[list[str], tuple[str, ...]]] = [
    (["nope"], ("nope",)),
    (["demo", "--duration", "x"], ("--duration", "(0, 86400]")),
    (["demo", "--duration", "-1"], ("--duration", "(0, 86400]")),
    (["demo", "--duration", "nan"], ("--duration", "nan")),
    (["demo", "--duration", "inf"], ("--duration",)),
    (["demo", "--duration", "0"], ("--duration",)),
    (["demo", "--objects", "16"], ("--objects", "0..15")),
    (["demo", "--signs", "-1"], ("--signs", "0..20")),
    (["demo", "--light-spots", "99"], ("--light-spots", "0..15")),
    (["demo", "--seed", "-1"], ("--seed", "0..4294967295")),
    (["demo", "--seed", str(2**32)], ("--seed",)),
    (["demo", "--speed", "1000"], ("--speed", "[-20, 100] m/s")),
    (["demo", "--speed", "nan"], ("--speed",)),
    (["demo", "--reset-at", "0"], ("--reset-at", "(0, 86400]")),
    (["demo", "--reset-at", "-3"], ("--reset-at",)),
    (["demo", "--reply-delay", "-1"], ("--reply-delay", "[0, 3600]")),
    (["demo", "--boot-fail", "-1"], ("--boot-fail", "0..1000")),
    (["demo", "--boot-test-bits", "0x10000"], ("--boot-test-bits", "0xFFFF")),
    (["demo", "--boot-test-bits", "NOT_A_BIT"], ("--boot-test-bits", "bits:")),
    (["demo", "--fatal", "999"], ("--fatal", "22")),
    (["demo", "--fatal", "intrinsic_calibration_mismtch"],
     ("--fatal", "did you mean INTRINSIC_CALIBRATION_MISMATCH")),
    (["demo", "--drop-reply", "NoSuchFunction"], ("--drop-reply", "GetEyeQVersions")),
    (["demo", "--drop-reply", "geteyeqversion"], ("--drop-reply", "did you mean GetEyeQVersions")),
    (["demo", "--drop-reply", "GetEyeQVersions:x"], ("--drop-reply", "1..1000000")),
    (["demo", "--drop-reply", "GetEyeQVersions:0"], ("--drop-reply", "1..1000000")),
    (["demo", "--drop-reply", "0x09/0x09"], ("--drop-reply", "0x09/0x09")),
    (["demo", "--stop-dasp", "FOO@3"], ("--stop-dasp", "FOO")),
    (["demo", "--stop-dasp", "obstacles@1"], ("--stop-dasp", "did you mean EYEQ_VIS_OBSTACLES")),
    (["demo", "--stop-dasp", "EYEQ_VIS_OBSTACLES_MSG@-1"], ("--stop-dasp", "[0, 86400]")),
    (["demo", "--stop-dasp", "EYEQ_VIS_OBSTACLES_MSG@"], ("--stop-dasp", "nothing after")),
    (["demo", "--stop-dasp", "HOST_VEH_STATE_MSG@1"], ("--stop-dasp", "HOST_VEH_STATE_MSG")),
    (["demo", "--stop-dasp", "0x99"], ("--stop-dasp", "0x99")),
    (["demo", "--sw", "7.5"], ("--sw", "8.1", "9.0")),
    (["demo", "--sw", "banana"], ("--sw", "9.0")),
    (["demo", "--ack-timeout", "0"], ("--ack-timeout", "(0, 60000] ms")),
    (["demo", "--transmit-timeout", "1e9"], ("--transmit-timeout", "(0, 60000] ms")),
    (["demo", "--scenario", "/nonexistent.csv"], ("--scenario", "/nonexistent.csv")),
    (["demo", "--capture", "/nonexistent-dir/x.pcapng"], ("--capture", "does not exist")),
    (["demo", "--capture", "DIR"], ("--capture", "directory")),
    (["demo", "--bogus"], ("--bogus",)),
    (["sim"], ("--listen", "--pty")),
    (["sim", "--listen", "udp://x:1"], ("--listen", "tcp://HOST:PORT")),
    (["sim", "--listen", "127.0.0.1:5000"], ("--listen", "tcp://HOST:PORT")),
    (["host", "--port", "listen://127.0.0.1:5"], ("--port", "listen://", "tcp://HOST:PORT")),
    (["host", "--port", "udp://127.0.0.1:5"], ("--port", "udp://", "tcp://HOST:PORT")),
    (["conformance", "--dut", "host", "--listen", "rfc2217://127.0.0.1:5"],
     ("--listen", "rfc2217://", "tcp://HOST:PORT")),
    (["replay", "FILE", "--listen", "tcp://127.0.0.1:99999"], ("--listen", "0..65535")),
    (["sim", "--listen", "tcp://127.0.0.1:70000"], ("--listen", "0..65535")),
    (["sim", "--pty", "--listen", "tcp://127.0.0.1:0"], ("--listen", "--pty")),
    (["sim", "--pty", "--accept-timeout", "-1"], ("--accept-timeout", "(0, 86400]")),
    (["sim", "--pty", "--duration", "nan"], ("--duration",)),
    (["sim", "--pty", "--speed", "3"], ("--speed", "not to sim")),
    (["sim", "--pty", "--scenario", "x.csv"], ("--scenario", "not to sim")),
    (["sim", "--pty", "--camera-only-aeb"], ("--camera-only-aeb", "not to sim")),
    (["host", "--port", "socket://127.0.0.1"], ("--port", "HOST:PORT")),
    (["host", "--port", "socket://127.0.0.1:0"], ("--port", "1..65535")),
    (["host", "--port", "socket://127.0.0.1:x"], ("--port", "integer")),
    (["host", "--port", "loop://"], ("--port", "loop://")),
    (["host", "--port", "/dev/nonexistent-eyeq"], ("--port", "/dev/nonexistent-eyeq")),
    (["host", "--port", "udp://127.0.0.1:5"], ("--port", "udp://")),
    (["host"], ("--port",)),
    ([*HOST, "--fatal", "22"], ("--fatal", "not to host")),
    ([*HOST, "--objects", "3"], ("--objects", "not to host")),
    ([*HOST, "--corrupt-eeprom"], ("--corrupt-eeprom", "not to host")),
    ([*HOST, "--stop-dasp", "0xE4@1"], ("--stop-dasp", "not to host")),
    ([*HOST, "--seed", "3"], ("--seed", "not to host")),
    ([*HOST, "--nvm", "/nonexistent-dir/nvm.json"], ("--nvm", "does not exist")),
    ([*HOST, "--duration", "-5"], ("--duration",)),
    (["dissect"], ("FILE",)),
    (["dissect", "--id", "zz", "FILE"], ("--id", "zz")),
    (["dissect", "--id", "-5", "FILE"], ("--id", "0..255")),
    (["dissect", "--id", "256", "FILE"], ("--id", "0..255")),
    (["dissect", "--name", "(", "FILE"], ("--name", "regular expression")),
    (["dissect", "--protocol", "XYZ", "FILE"], ("--protocol", "MESP")),
    (["dissect", "/nonexistent.pcapng"], ("FILE", "no such file")),
    (["dissect", "DIR"], ("FILE", "directory")),
    (["dissect", "--format", "nope", "FILE"], ("--format", "pcapng")),
    (["dissect", "--csv", "DIR", "--parquet", "DIR", "FILE"], ("--csv", "--parquet")),
    (["dissect", "--csv", "FILE", "FILE"], ("--csv", "not a directory")),
    (["dissect", "-", "-"], ("stdin",)),
    (["dissect", "--sw", "1.0", "FILE"], ("--sw", "9.0")),
    (["spec"], ("spec_command",)),
    (["spec", "show", "nope_nothing"], ("NAME", "nope_nothing")),
    (["spec", "show", "vis"], ("NAME", "EYEQ_VIS_OBSTACLES_MSG")),
    (["spec", "show", "0x99"], ("NAME", "0x99")),
    (["spec", "list", "--sw", "99"], ("--sw", "9.0")),
    (["wireshark", "--output", "/nonexistent-dir/x.lua"], ("--output", "does not exist")),
    (["wireshark", "--sw", "x"], ("--sw",)),
    # loop:// has nobody on it wherever a peer is named; replay's times are checked too
    (["monitor", "--port", "loop://"], ("--port", "loop://")),
    (["monitor", "--port", "socket://127.0.0.1"], ("--port", "HOST:PORT")),
    (["replay", "FILE", "--port", "loop://"], ("--port", "loop://", "tcp://HOST:PORT")),
    (["replay", "FILE", "--port", "listen://127.0.0.1:x"], ("--port", "listen://")),
    (["sim", "--port", "tcp://127.0.0.1:7"], ("--listen", "--pty")),
    (["sim", "--listen", "socket://127.0.0.1:7"], ("--listen", "tcp://HOST:PORT")),
    (["sim", "--listen", "pty"], ("--listen", "tcp://HOST:PORT")),
    (["replay", "FILE", "--into-host", "--duration", "nan"], ("--duration", "(0, 86400]")),
    (["replay", "FILE", "--into-host", "--duration", "-2"], ("--duration", "(0, 86400]")),
    (["replay", "FILE", "--port", "socket://127.0.0.1:1", "--lead", "-1"], ("--lead", "[0, 3600]")),
    # --sw is checked by every command that takes it; a side's option is refused where it
    # does not run, monitor included; the --jobs ranges at parse time
    (["plot", "FILE", "--link", "--sw", "7.7"], ("--sw", "9.0")),
    (["export", "FILE", "--vcd", "x.vcd", "--sw", "7.7"], ("--sw", "9.0")),
    (["replay", "FILE", "--into-host", "--sw", "7.7"], ("--sw", "9.0")),
    (["batch", "DIR", "--parquet", "out", "--sw", "7.7"], ("--sw", "9.0")),
    (["monitor", "--port", "socket://127.0.0.1:5", "--objects", "3"],
     ("--objects", "not to monitor --port")),
    (["monitor", "--replay", "FILE", "--capture", "x.pcapng"], ("--capture", "monitor --replay")),
    (["monitor", "--replay", "FILE", "--speed", "3"], ("--speed", "monitor --replay")),
    (["monitor", "--demo", "--channel-map", "h2e=a,e2h=b"], ("--channel-map", "--replay",
                                                               "monitor --demo")),
    (["monitor", "--port", "socket://127.0.0.1:5", "--format", "vcd"], ("--format", "--replay",
                                                                        "monitor --port")),
    (["sim", "--pty", "--can-protocol", "me8"], ("--can-protocol", "not to sim")),
    (["batch", "DIR", "--parquet", "out", "--local-cluster", "300"], ("--local-cluster", "1..256")),
    (["dissect", "--jobs", "-1", "FILE"], ("--jobs", "0..1024")),
]


def _fill(argv: list[str], files: dict[str, str]) -> list[str]:
    return [files.get(a, a) for a in argv]


@pytest.mark.parametrize(("argv", "words"), BAD, ids=[" ".join(a) or "(none)" for a, _ in BAD])
def test_bad_invocation_exits_2_with_one_line_naming_the_problem(
    argv: list[str], words: tuple[str, ...], files: dict[str, str],
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(_fill(argv, files)) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err.count("\n") == 1 and err.startswith("eyeq-spi: "), err
    assert "Traceback" not in err and "internal error" not in err, err
    for word in words:
        assert word.lower() in err.lower(), (word, err)
    assert captured.out == ""


def test_the_table_is_large_enough() -> None:
    assert len(BAD) >= 40


@pytest.mark.parametrize("argv", [["demo", "--fatal", "999"], ["dissect", "--id", "zz", "x"],
                                  ["host", "--port", "socket://127.0.0.1"]])
def test_a_real_process_prints_one_line_and_exits_2(argv: list[str]) -> None:
    r = subprocess.run([sys.executable, "-m", "eyeq_spi.cli", *argv], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr


def _parse(argv: list[str]) -> object:
    return build_parser().parse_args(argv)


def test_names_match_in_any_case_and_by_hex_id() -> None:
    a = _parse(["demo", "--stop-dasp", "eyeq_vis_obstacles_msg@2.5", "--stop-dasp", "0xE0",
                "--drop-reply", "geteyeqversions", "--drop-reply", "0x05/0x03:3",
                "--fatal", "intrinsic_calibration_mismatch", "--sw", "SW8_1",
                "--boot-test-bits", "0x0003"])
    assert a.stop_dasp == [("EYEQ_VIS_OBSTACLES_MSG", 2.5),  # type: ignore[attr-defined]
                           ("EYEQ_VIS_ROAD_DATA_MSG", 0.0)]
    assert a.drop_reply == [("GetEyeQVersions", 1),  # type: ignore[attr-defined]
                            ("GetEyeQExtendedState", 3)]
    assert a.fatal == 22 and a.sw == "sw8_1"  # type: ignore[attr-defined]
    assert _parse(["demo", "--fatal", "0x16"]).fatal == 22  # type: ignore[attr-defined]
    assert _parse(["dissect", "--id", "eyeq_vis_obstacles_msg", "--protocol", "dasp", "-"]
                  ).id == 0xE4  # type: ignore[attr-defined]


def test_boot_test_bits_by_name() -> None:
    from eyeq_spi.catalog.messages import catalog

    enum = catalog().enums["boot_test_result"]
    (bit0, v0), (bit1, v1) = sorted(enum.values.items())[:2]
    a = _parse(["demo", "--boot-test-bits", f"{v0.name.lower()}|{v1.name}"])
    assert a.boot_test_bits == (1 << bit0) | (1 << bit1)  # type: ignore[attr-defined]


# one address grammar: --listen tcp://HOST:PORT listens, --port URL connects, in every command
GRAMMAR: list[tuple[list[str], dict[str, object]]] = [
    (["sim", "--listen", "tcp://127.0.0.1:5000"], {"listen": "tcp://127.0.0.1:5000"}),
    (["sim", "--listen", "tcp://[::1]:0"], {"listen": "tcp://[::1]:0"}),
    (["sim", "--pty"], {"pty": True, "listen": None}),
    (["replay", "FILE", "--listen", "tcp://127.0.0.1:0"], {"listen": "tcp://127.0.0.1:0"}),
    (["replay", "FILE", "--port", "tcp://127.0.0.1:5"], {"port": "socket://127.0.0.1:5"}),
    (["conformance", "--dut", "host", "--listen", "tcp://0.0.0.0:0"],
     {"listen": "tcp://0.0.0.0:0"}),
    (["conformance", "--dut", "eyeq", "--port", "tcp://127.0.0.1:5"],
     {"port": "socket://127.0.0.1:5"}),
    (["host", "--port", "tcp://127.0.0.1:5"], {"port": "socket://127.0.0.1:5"}),
    (["host", "--port", "socket://127.0.0.1:5"], {"port": "socket://127.0.0.1:5"}),
    (["host", "--port", "rfc2217://10.0.0.2:4000"], {"port": "rfc2217://10.0.0.2:4000"}),
    (["host", "--port", "/dev/null"], {"port": "/dev/null"}),
    (["monitor", "--port", "tcp://127.0.0.1:5"], {"port": "socket://127.0.0.1:5"}),
]


@pytest.mark.parametrize(("argv", "want"), GRAMMAR, ids=[" ".join(a) for a, _ in GRAMMAR])
def test_one_address_grammar_in_every_command(
    argv: list[str], want: dict[str, object], files: dict[str, str],
    capsys: pytest.CaptureFixture[str],
) -> None:
    a = _parse(_fill(argv, files))
    assert {k: getattr(a, k) for k in want} == want
    assert capsys.readouterr().err == ""  # the new spelling: no note


def test_the_listener_prints_a_url_host_can_use() -> None:
    from eyeq_spi.phy.tcp import TcpListenAdapter

    ad = TcpListenAdapter("0.0.0.0", 0, timeout=0.1)
    try:
        url = ad.url
        assert url.startswith("tcp://127.0.0.1:")
        assert cli_args.connect_address(url) == "socket://" + url[len("tcp://"):]
    finally:
        ad.close()


def test_sim_config_gets_the_checked_values() -> None:
    from eyeq_spi.cli.options import sim_config

    cfg = sim_config(_parse(["demo", "--drop-reply", "GetEyeQVersions:2",
                             "--drop-reply", "getEyeQVersions", "--stop-dasp", "0xE4@1.5"]))
    assert cfg.drop_replies == {"GetEyeQVersions": 3}
    assert cfg.stop_dasp == {"EYEQ_VIS_OBSTACLES_MSG": 1.5}


@pytest.mark.parametrize(("query", "name"), [
    ("obstacles", "EYEQ_VIS_OBSTACLES_MSG"), ("0xE4", "EYEQ_VIS_OBSTACLES_MSG"),
    ("eyeq_vis_obstacles_msg", "EYEQ_VIS_OBSTACLES_MSG"), ("0x05/0x04", "GetEyeQVersions"),
    ("FATAL_ERROR", "fatal_error"), ("0x92", "Init_Params_Vision"),
    ("init_params_vision", "Init_Params_Vision"), ("0x41", "EYEQ_DIAGNOSTIC_MSG"),
])
def test_spec_show_finds_entries(query: str, name: str) -> None:
    assert cli_args.spec_entry(query) == name


def test_spec_show_by_hex_id_prints_the_layout(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["spec", "show", "0xE4"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("EYEQ_VIS_OBSTACLES_MSG") and "offset" in out


def test_did_you_mean() -> None:
    assert "GetEyeQVersions" in cli_args.did_you_mean("geteyeqversion", ["GetEyeQVersions"])
    assert cli_args.did_you_mean("zzzz", ["GetEyeQVersions"]) == ""


def test_help_lists_every_command_without_loading_the_catalogue() -> None:
    code = ("import sys, contextlib, io\n"
            "from eyeq_spi.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try: main(['--help'])\n"
            "    except SystemExit: pass\n"
            "print('eyeq_spi.catalog.messages' in sys.modules)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.stdout.strip() == "False", r.stderr


def test_parquet_without_pyarrow_gives_the_install_hint(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from eyeq_spi.dissect.output import TableWriter
    from eyeq_spi.errors import MissingExtra

    monkeypatch.setitem(sys.modules, "pyarrow", None)
    with pytest.raises(MissingExtra, match=r"eyeq-spi\[parquet\]"):
        TableWriter(str(tmp_path / "pq"), "parquet")


def test_sim_prints_the_exact_url_to_hand_to_host_on_stderr() -> None:
    """The address goes to stderr (and into the summary): stdout is the summary alone, so
    ``sim --json | jq`` works."""
    r = subprocess.run([sys.executable, "-m", "eyeq_spi.cli", "sim", "--listen",
                        "tcp://0.0.0.0:0", "--duration", "0.5", "--accept-timeout", "0.5",
                        "--json"], capture_output=True, text=True, timeout=60)
    kind, url = r.stderr.splitlines()[0].split()
    assert kind == "LISTEN" and url.startswith("tcp://127.0.0.1:")
    assert cli_args.connect_address(url) == "socket://" + url[len("tcp://"):]
    assert f"eyeq-spi host --port {url}" in r.stderr
    summary = json.loads(r.stdout)  # the whole of stdout is one JSON object
    assert summary["address"] == url and summary["connections"] == 0
    assert summary["problem"].startswith("no host connected") and r.returncode == 1


def test_the_parser_of_one_command_is_the_full_parser_for_that_command() -> None:
    """main() builds only the command it runs; TABLE must list every command with its help, in
    the order of the full parser, and each command's parser must not depend on the others."""
    import argparse

    from eyeq_spi.cli import TABLE

    def subs(p: argparse.ArgumentParser) -> tuple[dict[str, str], dict[str, str]]:
        act = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
        helps = {c.dest: str(c.help) for c in act._choices_actions}
        return helps, {n: sp.format_help() for n, sp in act.choices.items()}

    full_help, full = subs(build_parser())
    assert list(full_help.items()) == [(name, line) for name, (_, line) in TABLE.items()]
    assert build_parser("").format_help() == build_parser().format_help()
    for name in TABLE:
        helps, one = subs(build_parser(name))
        assert helps == full_help and one[name] == full[name], name


@pytest.mark.parametrize(("given", "expected"), [(None, "1"), ("3", "3")])
def test_the_cli_keeps_openblas_to_one_thread_unless_the_user_chose(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], given: str | None,
    expected: str,
) -> None:
    """numpy's OpenBLAS starts a spinning thread per core at import, which only burned CPU (no
    command does linear algebra): main() asks for one before anything imports numpy, and leaves
    a value the user set."""
    import os

    if given is None:
        monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OPENBLAS_NUM_THREADS", given)
    assert main(["spec", "list"]) == 0
    capsys.readouterr()
    assert os.environ["OPENBLAS_NUM_THREADS"] == expected
