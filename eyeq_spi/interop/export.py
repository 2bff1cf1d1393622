"""One pass over a capture feeding every export asked for: VCD waveforms (raw transfers, no
decoding), MDF4 and MCAP (through the dissector engine, so they hold exactly what ``eyeq-spi
dissect`` decodes). MDF4 alone is written from the dissect pipeline's records
(:func:`export_mdf`: the fast path where it applies); VCD and MCAP need the raw transfers
(:func:`export`)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable
from typing import IO, Any

from eyeq_spi import io as formats
from eyeq_spi.capture.pcapng_io import Transfer
from eyeq_spi.errors import OutputError
from eyeq_spi.logic.options import SpiOptions


def _open(path: str, mode: str) -> IO[Any]:
    try:
        if "b" in mode:
            return open(path, mode)
        return open(path, mode, encoding="utf-8", newline="\n")
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None


def _checked(path: str) -> str:
    """``path``, once a file can be written there (a session file is a zip, opened later)."""
    _open(path, "wb").close()
    return path


def export(transfers: Iterable[Transfer], *, source: str, sw: str | None = None,
           vcd: str | None = None, mdf: str | None = None, mcap: str | None = None,
           sr: str | None = None, sr_max_idle: float | None = None,
           spi: SpiOptions | None = None, vcd_max_idle: float | None = None,
           progress: Callable[[int], None] | None = None,
           mcap_extra: Callable[[Any, Any], Any] | None = None) -> dict[str, Any]:
    """Write the outputs asked for in one pass over ``transfers``; ``progress(count)`` is
    called after each transfer (a progress bar's update). ``mcap_extra(writer, codec)``: more
    topics for the MCAP file (the Foxglove scene), an object whose ``add(record)`` takes every
    dissector record and whose ``summary()`` joins the MCAP's."""
    from eyeq_spi.codec.message import MessageCodec
    from eyeq_spi.dissect.engine import Dissector

    codec = MessageCodec(sw)
    with contextlib.ExitStack() as stack:
        vcd_w = mdf_w = mcap_w = sr_w = None
        if sr:
            from eyeq_spi.logic.sr_write import SrWriter

            sr_w = SrWriter(_checked(sr), spi, max_idle=sr_max_idle)
            stack.callback(sr_w.close)
        if vcd:
            from eyeq_spi.logic.vcd_write import VcdWriter

            vcd_w = VcdWriter(stack.enter_context(_open(vcd, "w")), spi, max_idle=vcd_max_idle)
        if mdf:
            mdf_w = formats.load("mdf4", formats.RECORD_WRITER, what="--mdf")(
                mdf, codec, source=source)
        if mcap:
            mcap_w = formats.load("mcap", formats.RECORD_WRITER, what="--mcap")(
                stack.enter_context(_open(mcap, "wb")), sw=codec.sw, source=source)
        extra = mcap_extra(mcap_w, codec) if mcap_w is not None and mcap_extra else None
        dis = Dissector(codec=codec) if (mdf_w or mcap_w) else None
        count = 0
        for transfer in transfers:
            count += 1
            if progress is not None:
                progress(count)
            if vcd_w is not None:
                vcd_w.write(transfer)
            if sr_w is not None:
                sr_w.write(transfer)
            if dis is not None:
                _deliver(dis.feed(transfer), transfer, count - 1, mcap_w, extra, mdf_w)
        if dis is not None:  # what the dissector held at the end: MCAP only, as before
            _deliver(dis.finish(), None, -1, mcap_w, extra, None)
        written = []
        summary: dict[str, Any] = {"transfers": count, "sw": codec.sw}
        if vcd_w is not None:
            vcd_w.close()
            written.append(f"{vcd} ({vcd_w.count} transfers, {vcd_w.delayed} moved to keep "
                           "their channel's gap)")
            summary["vcd"] = {"path": vcd, "transfers": vcd_w.count, "delayed": vcd_w.delayed}
        if sr_w is not None:
            sr_w.close()
            written.append(f"{sr} ({sr_w.count} transfers, {sr_w.delayed} moved to keep "
                           f"their channel's gap; {sr_w.sink.samples:,} samples at "
                           f"{sr_w.samplerate / 1e6:g} MHz)")
            summary["sr"] = {"path": sr, "transfers": sr_w.count, "delayed": sr_w.delayed,
                             "samples": sr_w.sink.samples, "samplerate": sr_w.samplerate}
        if mdf_w is not None:
            mdf_w.close()
            written.append(f"{mdf} ({len(mdf_w.groups)} channel groups, {mdf_w.messages} "
                           "messages)")
            summary["mdf"] = {"path": mdf, "groups": len(mdf_w.groups),
                              "messages": mdf_w.messages}
        if mcap_w is not None:
            mcap_w.close()
            written.append(f"{mcap} ({len(mcap_w.channels)} topics, {mcap_w.messages} "
                           "decoded messages)")
            summary["mcap"] = {"path": mcap, "topics": len(mcap_w.channels),
                               "messages": mcap_w.messages}
            if extra is not None:
                summary["mcap"].update(extra.summary())
                written.extend(extra.written())
        summary["written"] = written
        return summary


def _deliver(records: Iterable[dict[str, Any]], transfer: Transfer | None, index: int,
             mcap_w: Any, extra: Any, mdf_w: Any) -> None:
    """The dissector's records to every writer that takes them; the frame record of ``transfer``
    (the transfer at ``index``) goes to the MCAP with its raw bytes."""
    for record in records:
        if mcap_w is not None:
            if transfer is not None and record["kind"] == "frame" and record["index"] == index:
                mcap_w.transfer(transfer, record)
            else:
                mcap_w.write(record)
        if extra is not None:
            extra.add(record)
        if mdf_w is not None:
            mdf_w.write(record)


def export_mdf(records: Iterable[dict[str, Any]], mdf: str, *, source: str,
               sw: str | None = None) -> dict[str, Any]:
    """The MDF4 file ``mdf`` from the dissector's records of one capture (what
    :func:`eyeq_spi.dissect.pipeline.dissect_files` hands out), in one pass; the summary of
    :func:`export` with ``mdf`` alone."""
    from eyeq_spi.codec.message import MessageCodec
    from eyeq_spi.interop.mdf import MdfWriter

    codec = MessageCodec(sw)
    mdf_w = MdfWriter(mdf, codec, source=source)
    transfers = 0
    for record in records:
        if record["kind"] == "frame":
            transfers += 1  # one frame record per transfer
        mdf_w.write(record)
    mdf_w.close()
    return {"transfers": transfers, "sw": codec.sw,
            "mdf": {"path": mdf, "groups": len(mdf_w.groups), "messages": mdf_w.messages},
            "written": [f"{mdf} ({len(mdf_w.groups)} channel groups, {mdf_w.messages} "
                        "messages)"]}
