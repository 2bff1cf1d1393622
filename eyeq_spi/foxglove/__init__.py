"""What the EyeQ sees, in Foxglove's own schemas (the ``foxglove-sdk`` package, the
``[foxglove]`` extra): the scene as ``foxglove.SceneUpdate`` topics, the vehicle frame as
``foxglove.FrameTransform``, link events and host transitions as ``foxglove.Log``, and plain
numeric topics for plots.

- :mod:`.topics`: the topic names and the :class:`~.topics.Sink` every output implements;
- :mod:`.scene`: a :class:`~eyeq_spi.plot.perceived.Scene` as SceneUpdate messages;
- :mod:`.feed`: decoded messages and events in, messages on the topics out (one feed for a
  capture's records and for a live host);
- :mod:`.mcap_sink` (``export --mcap``) and :mod:`.server` (``--foxglove HOST:PORT``): the sinks;
- :mod:`.live`: a running host's decoded messages published at most at the DASP rate;
- :mod:`.layout`: the Foxglove layout (3D panel, plots, log) for these topics.
"""
