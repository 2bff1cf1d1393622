"""Fault campaigns against the stack: a seeded lossy channel for the memory pair's fault hook,
the lossy-channel soak and the EyeQ reset campaign."""
