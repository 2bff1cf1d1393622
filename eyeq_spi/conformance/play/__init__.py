"""The side we play (``eyeq``, ``host``), the fault-injecting shim and the session that runs
them; independent of ``judges``."""
