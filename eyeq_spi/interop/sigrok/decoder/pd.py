"""The decoder class (libsigrokdecode API 3). The decoding itself is the project's:
``eyeq_spi.interop.annotate.Annotator`` runs the dissector engine on each chip-select transfer."""

from typing import Any, ClassVar, cast

import sigrokdecode as srd

from eyeq_spi.interop.annotate import ROWS, Annotator, short_texts


class Decoder(srd.Decoder):  # type: ignore[misc]
    api_version = 3
    id = "eyeq_spi"
    name = "EyeQ4 SPI"
    longname = "EyeQ4 SPI link, transport and messages"
    desc = "EyeQ4 <-> host (Aurix) SPI: link frames, transport, MESP/DASP messages."
    license = "unknown"
    inputs: ClassVar[list[str]] = ["spi"]
    outputs: ClassVar[list[str]] = []
    tags: ClassVar[list[str]] = ["Automotive"]
    options: ClassVar[tuple[dict[str, Any], ...]] = (
        {"id": "direction", "desc": "SPI channel", "default": "h2e", "values": ("h2e", "e2h")},
        {"id": "line", "desc": "Data line of the frames", "default": "mosi",
         "values": ("mosi", "miso")},
        {"id": "sw", "desc": "SW release (empty: newest)", "default": ""},
    )
    annotations = ROWS
    annotation_rows = tuple((key, label, (i,)) for i, (key, label) in enumerate(ROWS))

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.samplerate: float | None = None
        self.annotator: Annotator | None = None

    def metadata(self, key: int, value: Any) -> None:
        if key == srd.SRD_CONF_SAMPLERATE:
            self.samplerate = float(value)

    def start(self) -> None:
        self.out_ann = self.register(srd.OUTPUT_ANN)
        opts = cast(dict[str, Any], self.options)  # a dict per instance, set by libsigrokdecode
        self.line = str(opts["line"])
        self.annotator = Annotator(str(opts["direction"]), str(opts["sw"]) or None)

    def decode(self, ss: int, es: int, data: Any) -> None:
        if data[0] != "TRANSFER" or self.annotator is None:
            return
        words = data[1] if self.line == "mosi" else data[2]
        payload = bytes(w.val & 0xFF for w in words)
        time = ss / self.samplerate if self.samplerate else None
        for a_ss, a_es, row, text in self.annotator.transfer(payload, ss, es, time):
            self.put(a_ss, a_es, self.out_ann, [row, short_texts(row, text)])
