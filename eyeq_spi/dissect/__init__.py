"""Capture dissection: inputs (raw, hex, pcapng), the record engine, outputs and statistics."""
