"""Codecs built from specs/: DASP, 0x41/0x10, MESP, init bit tables, E2E."""
