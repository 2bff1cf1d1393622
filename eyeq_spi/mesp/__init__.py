"""MESP (seed 004 §7.1.1): a sans-IO client with tag matching, deadlines and retries, and a
server dispatch table. Both speak whole application messages; a transport carries them."""
