"""The judges: one function per case that reads the recorded traces and returns a verdict
(``link``: seed 004 §6 and the transport; ``app``: MESP and DASP; ``flow``: the application
flows; ``verdict``: the outcome and context they share). Independent of ``play``: a judge sees
only the trace, never the script that produced it."""
