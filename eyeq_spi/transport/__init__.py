"""Transport layer (seed 004 §6.1-6.2): segmentation and reassembly. Sans-IO."""

from eyeq_spi.transport.connection import TransportConfig, TransportConnection
from eyeq_spi.transport.events import (
    MessageReceived,
    MessageSendFailed,
    MessageSent,
    TransferAborted,
)
from eyeq_spi.transport.segment import segment

__all__ = [
    "MessageReceived", "MessageSendFailed", "MessageSent", "TransferAborted", "TransportConfig",
    "TransportConnection", "segment",
]
