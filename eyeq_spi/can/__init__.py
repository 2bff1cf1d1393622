"""Mobileye CAN output (seeds 000, 001, 003): DBCs generated from ``specs/can/``, a live gateway
from decoded DASP data, and a CAN log decoder. Sits beside the host and the simulator: it only
uses the host's public hooks (subscribers, its scenario, the runner's node slot)."""

from eyeq_spi.can.dbc import build_database, dbc_text
from eyeq_spi.can.gateway import CanFrame, CanGateway

__all__ = ["CanFrame", "CanGateway", "build_database", "dbc_text"]
