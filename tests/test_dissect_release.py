"""The SW release travels with the data: captures record it (``eyeq-spi sw=<release>`` on the
Section Header Block and the first packet), every reader uses it, a capture without it takes it
from the traffic, and ``--sw`` overrides with a one-line warning."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from eyeq_spi.capture.pcapng_io import CaptureWriter, read_pcapng, recorded_release
from eyeq_spi.catalog.messages import catalog, sw_release_text
from eyeq_spi.cli import main
from eyeq_spi.codec.message import DASP_PROTOCOL
from eyeq_spi.dissect import release as rel
from eyeq_spi.dissect.pipeline import SMALL_INPUT
from eyeq_spi.transport.segment import CONSECUTIVE, FIRST
from eyeq_spi.twins import EXACT_ENV

pytestmark = pytest.mark.twin  # runs an exact/fast twin: also run with EYEQ_SPI_EXACT=1

RELEASES = [sw_release_text(k) for k in catalog().sw_versions]


def _run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def captures(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """1.5 s of the emulator in every release specs/ knows (Running Vision at 0.53 s)."""
    d = tmp_path_factory.mktemp("releases")
    out = {}
    for r in RELEASES:
        path = d / f"sw{r}.pcapng"
        assert main(["demo", "--virtual-time", "--duration", "1.5", "--sw", r, "--capture",
                     str(path), "--json"]) == 0
        out[r] = path
    return out


def _hex(path: Path, dst: Path, keep: Any = None) -> Path:
    """The capture as hex text (no release recorded), optionally only some records."""
    with path.open("rb") as fh, dst.open("w") as out:
        for r in read_pcapng(fh):
            if keep is None or keep(r):
                out.write(f"{r.time:.6f} {r.direction} {r.data.hex()}\n")
    return dst


def test_the_writer_records_the_release_on_the_shb_and_the_first_packet(tmp_path: Path) -> None:
    from pcapng import FileScanner, blocks

    path = tmp_path / "c.pcapng"
    with CaptureWriter(path, "8.1") as w:
        for i in range(3):
            w.write("h2e" if i % 2 else "e2h", i * 1e-3, bytes(128))
    data = path.read_bytes()
    assert recorded_release(data[:4096]) == "sw8_1"
    with path.open("rb") as fh:
        got = list(FileScanner(fh))
    shb = got[0]
    assert isinstance(shb, blocks.SectionHeader)
    assert shb.options["opt_comment"] == "eyeq-spi sw=8.1"
    assert shb.options["shb_userappl"] == "eyeq-spi"
    epbs = [b for b in got if isinstance(b, blocks.EnhancedPacket)]
    assert len(epbs) == 3 and epbs[0].options["opt_comment"] == "eyeq-spi sw=8.1"
    assert "opt_comment" not in epbs[1].options
    with path.open("rb") as fh:  # the readers see the same transfers as before
        recs = list(read_pcapng(fh))
    assert [(r.time, r.direction, r.data) for r in recs] == [
        (0.0, "e2h", bytes(128)), (0.001, "h2e", bytes(128)), (0.002, "e2h", bytes(128))]


@pytest.mark.parametrize("exact", ["1", "0"], ids=["reference", "fast"])
def test_a_capture_of_every_release_dissects_clean(captures: dict[str, Path], exact: str,
                                                   capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Before captures carried their release, every release but the newest read as broken."""
    monkeypatch.setenv(EXACT_ENV, exact)
    for r, path in captures.items():
        assert path.stat().st_size >= SMALL_INPUT  # the fast path reads it unless exact
        rc, out, err = _run(capsys, "dissect", str(path), "--stats", "--json")
        st = json.loads(out)
        assert (rc, st["protocol_errors"], st["sw"], st["sw_source"], err) == \
            (0, 0, r, "recorded in the capture", ""), r


def test_both_paths_give_the_same_records(captures: dict[str, Path],
                                          capsys: pytest.CaptureFixture[str],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    for r, path in captures.items():
        outs = []
        for exact in ("1", "0"):  # the references, then the fast path
            monkeypatch.setenv(EXACT_ENV, exact)
            outs.append(_run(capsys, "dissect", str(path), "--json")[:2])
        assert outs[0] == outs[1] and outs[0][0] == 0, r


def test_without_the_comment_the_release_comes_from_the_traffic(
        captures: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    hexfile = _hex(captures["8.1"], tmp_path / "c.hex")
    rc, out, err = _run(capsys, "dissect", str(hexfile), "--stats", "--json")
    st = json.loads(out)
    assert (rc, st["protocol_errors"], st["sw"], err) == (0, 0, "8.1", "")
    assert st["sw_source"] in ("GetEyeQVersions reply", "boot status")
    # from the middle of the run: the periodic base diagnostic status names it
    late = _hex(captures["8.1"], tmp_path / "late.hex", lambda r: r.time > 1.0)
    st = json.loads(_run(capsys, "dissect", str(late), "--stats", "--json")[1])
    assert (st["sw"], st["sw_source"]) == ("8.1", "EYEQ_BASE_DIAG_STATUS_MSG")


def _without_base_diag(transfers: list[Any]) -> list[Any]:
    """The transfers without EYEQ_BASE_DIAG_STATUS_MSG (DASP 0xA0, whose bytes name the
    release): its first frames (T1: bytes 8..11 the total, then the message) and the
    consecutive frames of their transfer IDs, per direction."""
    dropped: dict[str | None, int | None] = {}
    kept = []
    for transfer in transfers:
        kind, transfer_id = transfer.data[6], transfer.data[7]
        if kind == FIRST:
            message = transfer.data[12:14]
            dropped[transfer.direction] = (transfer_id if message == bytes([DASP_PROTOCOL, 0xA0])
                                           else None)
        if kind in (FIRST, CONSECUTIVE) and transfer_id == dropped.get(transfer.direction):
            continue
        kept.append(transfer)
    return kept


def test_else_the_release_whose_dasp_layouts_fit(captures: dict[str, Path]) -> None:
    with captures["5.0"].open("rb") as fh:  # nothing left in the traffic names the release
        late = _without_base_diag([r for r in read_pcapng(fh) if r.time > 1.0])
    found = rel.infer_release(late)
    assert found is not None and found[1].startswith("DASP payload lengths")
    assert "5.0" in found[1]
    from eyeq_spi.dissect.engine import iter_records

    errors = [r for r in iter_records(late, sw=found[0]) if r.get("errors")]
    assert errors == []
    wrong = [r for r in iter_records(late, sw="9.0") if r.get("errors")]
    assert wrong  # the newest release does not fit this capture


def test_sw_overrides_with_one_line_naming_both(captures: dict[str, Path],
                                                capsys: pytest.CaptureFixture[str]) -> None:
    rc, out, err = _run(capsys, "dissect", str(captures["8.1"]), "--sw", "9.0", "--stats",
                        "--json")
    assert json.loads(out)["sw"] == "9.0" and json.loads(out)["sw_source"] == "--sw"
    assert err.count("\n") == 1 and "SW 9.0" in err and "SW 8.1" in err and rc == 1
    rc, out, err = _run(capsys, "dissect", str(captures["8.1"]), "--sw", "8.1", "--stats")
    assert rc == 0 and err == ""


def _cmds(path: Path, tmp_path: Path) -> Iterator[tuple[str, list[str]]]:
    import importlib.util

    yield "replay", ["replay", str(path), "--into-host", "--json"]
    yield "monitor", ["monitor", "--replay", str(path), "--pace", "0"]
    yield "monitor", ["monitor", "--replay", str(path), "--passive", "--pace", "0"]
    if importlib.util.find_spec("mcap") is not None:
        yield "export", ["export", str(path), "--mcap", str(tmp_path / "x.mcap"), "--json"]
    if importlib.util.find_spec("matplotlib") is not None:
        yield "plot", ["plot", str(path), "--timing", "-o", str(tmp_path / "t.png")]


def test_the_other_readers_use_the_capture_release(captures: dict[str, Path], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    for name, argv in _cmds(captures["8.1"], tmp_path):
        rc, out, err = _run(capsys, *argv)
        assert rc == 0 and err == "", (name, err)
        if name == "replay":
            summary = json.loads(out)
            assert summary["ok"] and summary.get("decode_errors", 0) == 0
        rc, out, err = _run(capsys, *argv, "--sw", "9.0")
        assert err.count("\n") == 1 and "SW 8.1" in err, (name, err)


# -- several files --------------------------------------------------------------------------
def test_several_files_each_with_its_file_its_release_and_its_own_rates(
        captures: dict[str, Path], capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    a, b = str(captures["8.1"]), str(captures["9.0"])
    rc, out, _ = _run(capsys, "dissect", a, b, "--stats", "--json")
    per_a, per_b, total = (json.loads(x) for x in out.splitlines())
    assert rc == 0 and (per_a["file"], per_b["file"], total["file"]) == (a, b, None)
    assert (per_a["sw"], per_b["sw"], total["files"]) == ("8.1", "9.0", 2)
    name = "HOST_VEH_STATE_MSG"
    rates = [s["messages"][name] for s in (per_a, per_b, total)]
    assert rates[2]["count"] == rates[0]["count"] + rates[1]["count"]
    # the two runs overlap in time: a rate over both files at once would be about twice this
    assert rates[2]["mean_hz"] == pytest.approx(rates[0]["mean_hz"], rel=0.05)
    assert rates[2]["mean_hz"] < rates[2]["nominal_hz"] * 1.1
    rc, out, _ = _run(capsys, "dissect", a, b, "--json")
    files = [json.loads(x)["file"] for x in out.splitlines()]
    assert rc == 0 and files[0] == a and files[-1] == b
    assert files == sorted(files, key=(a, b).index)  # every record, in file order
    rc, out, _ = _run(capsys, "dissect", a, b, "--id", "0xA0", "--no-tree")
    assert [x for x in out.splitlines() if x.startswith("===")] == [f"=== {a}", f"=== {b}"]


@pytest.mark.parametrize("mode", [["--json"], ["--stats"], ["--stats", "--json"]])
def test_jobs_print_what_one_file_at_a_time_prints(captures: dict[str, Path], mode: list[str],
                                                   capsys: pytest.CaptureFixture[str],
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    files = [str(captures[r]) for r in ("8.1", "9.0", "5.0")]
    for exact in ("1", "0"):  # the references serially, or the fast path (workers for --jobs)
        monkeypatch.setenv(EXACT_ENV, exact)
        serial = _run(capsys, "dissect", *files, *mode)
        assert serial[0] == 0
        assert _run(capsys, "dissect", "--jobs", "2", *files, *mode) == serial


def test_a_fault_still_comes_after_the_transfers_before_it(captures: dict[str, Path]) -> None:
    """The transfers read to find the release are kept; a fault among them is raised after
    them, as the reader alone would."""
    import io

    from eyeq_spi.errors import InputError

    data = (captures["8.1"].read_bytes().replace(b"eyeq-spi sw=8.1", b"another tool   "))
    at = 0  # the 40th block among the first transfers gets an impossible length
    for _ in range(40):
        at += int.from_bytes(data[at + 4:at + 8], "little")
    bad = data[:at + 4] + (13).to_bytes(4, "little") + data[at + 8:]
    cap = rel.open_capture(io.BytesIO(bad), name="bad")
    got = []
    with pytest.raises(InputError, match="malformed pcapng"):
        for r in cap.transfers:
            got.append(r)
    assert len(got) > 10
