"""MESP (seed 004 §7.1.1): a sans-IO client with tag matching, deadlines and retries, and a
server dispatch table. Both speak whole application messages; a transport carries them."""

from eyeq_spi.mesp.client import MespClient, MespCompleted, MespFailed, StaleReply
from eyeq_spi.mesp.replies import MespFailure, MespReply, MespResult, unwrap
from eyeq_spi.mesp.server import MespServer

__all__ = ["MespClient", "MespCompleted", "MespFailed", "MespFailure", "MespReply", "MespResult",
           "MespServer", "StaleReply", "unwrap"]
