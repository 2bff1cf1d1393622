"""The judges: one function per case over the recorded traces; they never see ``play``."""
