"""The tester's side of a session: the scripted EyeQ or host we play against the implementation
under test (``eyeq``, ``host``), the fault-injecting shim between them and the session that runs
both in virtual or real time. Independent of ``judges``: both read only the shared model and the
recorded trace."""
