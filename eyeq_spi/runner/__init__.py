"""Runners feed sans-IO nodes with transfers and ``now``. They are the only code that reads a
clock or sleeps: :class:`VirtualRunner` for tests and fast simulation, :class:`RealTimeRunner`
for a real adapter."""

from eyeq_spi.runner.node import Node
from eyeq_spi.runner.realtime import RealTimeRunner
from eyeq_spi.runner.virtual import VirtualRunner

__all__ = ["Node", "RealTimeRunner", "VirtualRunner"]
