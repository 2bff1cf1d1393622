"""Bench tools: exports of captures for the tools of the field (VCD for PulseView, MDF4 for
asammdf/CANape, MCAP for Foxglove), the sigrok protocol decoder and replay of captures into a
host under test or the built-in host emulator."""
